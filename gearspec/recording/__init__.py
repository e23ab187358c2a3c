from .load import *  # noqa: F401,F403
from .load import _unwrap_theta  # noqa: F401
