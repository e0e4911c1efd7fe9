"""The textbook table: every method next to every closed form, computed at run time."""

from __future__ import annotations

import pytest

from flatland.core.stats import family_quantile
from flatland.core.validate import ValidationError
from flatland.integrals import INTEGRALS
from flatland.textbook_report import DEFAULT_METHODS, explain, textbook_rows, textbook_table

# Biased by construction (Loubet et al. 2019, Sec. 3.2 and 4.2): naive drops every moving jump; one
# translation per sample cannot follow two jumps moving at different speeds.
EXPECTED_FLAGS = {(name, "naive") for name in INTEGRALS if name != "smooth"} | {
    ("leibniz_seed", "reparam, no kernel"),
    ("two_steps", "reparam, no kernel"),
    ("arc_stretch", "reparam, no kernel"),
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
    """The 36 rows' 99 % intervals are simultaneous (each ± 3.63 standard errors: an unbiased table
    shows no flag with probability 0.99); with seed 0 the biased entries, and only they, fall outside.
    A row is flagged exactly when its interval excludes the closed form."""
    flagged = {(r.integral, r.label) for r in rows if r.flagged}
    assert flagged == EXPECTED_FLAGS
    q = family_quantile(len(rows))
    assert abs(q - 3.63) < 0.005 and all(r.quantile == q for r in rows)
    for r in rows:
        low, high = r.derivative - q * r.stderr, r.derivative + q * r.stderr
        assert r.flagged == (not low - 1e-12 <= r.closed_form <= high + 1e-12), r
    # the jump term is exact: where the interior term vanishes, the boundary estimate is the closed form
    assert all(r.z == 0.0 for r in rows if r.method == "boundary" and r.integral != "smooth")


def test03_table_text_lists_every_integral_and_marks_the_flags(rows):
    """The kernel variants beside the plain translation, no z of ±inf (an exact estimate says so), a
    legend, and one line per flagged row saying why."""
    text = textbook_table(rows=rows)
    lines = text.splitlines()
    assert lines[0].startswith("Textbook integrals") and "closed form" in lines[1]
    for name in INTEGRALS:
        assert any(line.startswith(name) for line in lines)
    assert sum(line.rstrip().endswith(" BIASED") for line in lines) == len(EXPECTED_FLAGS)
    for name in INTEGRALS:  # reparam without, then with its kernels, on consecutive lines
        block = [r.label for r in rows if r.integral == name]
        k = block.index("reparam, no kernel")
        assert block[k + 1 : k + 3] == ["reparam, kernel kappa=100", "reparam, kernel kappa=100, paired"]
    assert "inf" not in text and "99 % interval" in text
    leibniz_naive = next(line for line in lines if line.startswith("leibniz_seed"))
    assert "0 exactly (σ = 0)" in leibniz_naive and " — " in leibniz_naive
    why = lines[lines.index(next(line for line in lines if line.startswith("Why the"))) + 1 :]
    assert len(why) == len(EXPECTED_FLAGS) and all("predicted" in line and "measured" in line for line in why)
    assert all(
        "one translation per sample follows only the nearer" in line for line in why if "no kernel" in line
    )


def test04_bad_arguments_name_the_field():
    with pytest.raises(ValidationError, match=r"^n: "):
        textbook_rows(n=0)
    with pytest.raises(ValidationError, match=r"^seed: "):
        textbook_table(seed=-3)


def test05_each_explanation_predicts_the_bias_it_measures(rows):
    """The predicted bias in each flagged row's line is the closed form of that estimator's bias
    (naive: minus the jump term; the translation: tests/flatland/test_estimators.py test06), and the
    measured one lies within the row's interval of it (or equals it, without spread)."""
    for r in (r for r in rows if r.flagged):
        line = explain(r, rows)
        predicted = float(line.split("bias ")[1].split(" predicted")[0])
        error = r.derivative - r.closed_form
        assert abs(error - predicted) <= r.quantile * r.stderr + 0.005 * abs(predicted), line
        if "no kernel" in line:
            assert "with kernel kappa=100:" in line  # the unbiased kernel variant quoted beside it
