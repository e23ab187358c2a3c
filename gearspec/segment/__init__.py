from .plateaus import *  # noqa: F401,F403
from .plateaus import _position_noise, _sweeps  # noqa: F401
