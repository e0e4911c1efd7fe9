"""The textbook table: every method next to every closed form, computed at run time."""

from __future__ import annotations

import pytest

from flatland.core.validate import ValidationError
from flatland.integrals import INTEGRALS
from flatland.textbook_report import DEFAULT_METHODS, Z_FLAG, textbook_rows, textbook_table

# Biased by construction (Loubet et al. 2019, Sec. 3.2 and 4.2): naive drops every moving jump; one
# translation per sample cannot follow two jumps moving at different speeds.
EXPECTED_FLAGS = {(name, "naive") for name in INTEGRALS if name != "smooth"} | {
    ("leibniz_seed", "reparam"),
    ("two_steps", "reparam"),
    ("arc_stretch", "reparam"),
}


@pytest.fixture(scope="module")
def rows():
    return textbook_rows(n=20_000, seed=0)


def test01_one_row_per_integral_and_method_with_its_closed_form(rows):
    assert len(rows) == len(INTEGRALS) * len(DEFAULT_METHODS)
    for r in rows:
        integral = INTEGRALS[r.integral]
        assert r.theta == integral.default_theta and r.closed_form == integral.derivative(r.theta)
        assert r.n == 20_000 and r.stderr >= 0.0


def test02_flags_exactly_the_biased_estimators(rows):
    """With seed 0 the unbiased entries (~28 of them) stay within the two-sided 99.9 % quantile
    (3.29 standard errors; a false flag has probability 0.001 each); the biased ones are far out."""
    flagged = {(r.integral, r.label) for r in rows if r.flagged}
    assert flagged == EXPECTED_FLAGS
    assert abs(Z_FLAG - 3.2905) < 1e-4
    # the jump term is exact: where the interior term vanishes, the boundary estimate is the closed form
    assert all(r.z == 0.0 for r in rows if r.method == "boundary" and r.integral != "smooth")


def test03_table_text_lists_every_integral_and_marks_the_flags(rows):
    text = textbook_table(rows=rows)
    lines = text.splitlines()
    assert lines[0].startswith("Textbook integrals") and "closed form" in lines[1]
    for name in INTEGRALS:
        assert any(line.startswith(name) for line in lines)
    assert sum(" BIASED " in line for line in lines) == len(EXPECTED_FLAGS)
    assert "reparam kappa=100 paired" in text and "±" in text


def test04_bad_arguments_name_the_field():
    with pytest.raises(ValidationError, match=r"^n: "):
        textbook_rows(n=0)
    with pytest.raises(ValidationError, match=r"^seed: "):
        textbook_table(seed=-3)
