"""The command line's law lists come from the term registry (issue 11): a law registered once is
accepted by ``gearspec fit --law``, ``gearspec diagnose --law`` and ``gearspec discover --compare``,
and the lists of the existing laws keep their order (the ``--help`` text)."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from gearspec.cli import build_parser
from gearspec.cli.fit import law_choices
from gearspec.discover import PAPER_LAWS
from gearspec.terms import BASE_LAWS, BaseLaw, register_law


def _choices(command: str) -> tuple:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    law = next(a for a in sub.choices[command]._actions if a.dest == "law")
    return tuple(law.choices)


def test_law_lists_of_the_existing_laws_keep_their_order():
    assert law_choices() == ("coulomb_viscous", "stribeck", "silo4", "lola8", "lola11")
    assert PAPER_LAWS == law_choices()
    assert _choices("fit") == ("silo4", "stribeck", "lola8", "lola11", "coulomb_viscous")
    assert _choices("diagnose") == ("silo4", "stribeck", "coulomb_viscous", "lola8", "lola11")
    assert law_choices("nope", "lola8") == ("lola8", "coulomb_viscous", "stribeck", "silo4", "lola11")


def test_a_law_registered_once_is_offered_by_every_command():
    law = BaseLaw("test_quadratic", ("tau_c", "c"), ("Nm", "Nm s^2/rad^2"),
                  lambda speed, load, tau_c, c: tau_c + c * speed * speed, description="test law",
                  linear=("tau_c", "c"), columns=lambda s, load: np.column_stack([np.ones_like(s), s * s]))
    register_law(law)
    try:
        assert _choices("fit")[-1] == "test_quadratic"
        assert _choices("diagnose")[-1] == "test_quadratic"
        sub = build_parser().parse_args(["discover", "x.csv"])
        assert sub.compare.split(",")[-1] == "test_quadratic"
    finally:
        BASE_LAWS.pop("test_quadratic")
    assert "test_quadratic" not in law_choices()


@pytest.mark.parametrize("argv", [["fit", "x.csv", "--law", "none"], ["diagnose", "x.csv", "--law", "friction"]])
def test_a_law_without_parameters_or_unknown_is_refused(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    assert exc.value.code == 2
    assert "invalid choice" in capsys.readouterr().err
