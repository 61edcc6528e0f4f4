"""Eq. 8 and its inverses, Gamma, the racket's acceleration AC and eq. 10's 2 x 2 eigenvalues
are written once (``model/params.py``, ``model/linear.py``): no other module spells them out.

The code of every module is read as tokens (comments and strings dropped, spaces removed),
and searched for the ways a hurried implementer writes these formulas again."""

import io
import re
import tokenize
from pathlib import Path

import pytest

import bounce_cli

PACKAGE = Path(bounce_cli.__file__).parent

#: formula -> (the patterns of its spellings, the modules allowed to hold it)
FORMULAS = {
    # eq. 8: cos theta~ = pi (1 - alpha) / (1 + alpha) g / (omega^2 a_r), and inverted
    "eq. 8": ([r"pi\*\(1(\.0)?-alpha\)/\(1(\.0)?\+alpha\)",
               r"\*\*2\*[a-z_.]+/\((math\.|np\.)?pi\*[a-z_.]*g\)"],
              {"model/params.py"}),
    # Gamma = a_r omega^2 / g
    "Gamma": ([r"(omega|w)\*\*2/(params\.|p\.|self\.)?g\b",
               r"amplitude\*(omega|w)\*\*2/", r"\(2(\.0)?\*(math\.|np\.)?pi/[a-z_.]+\)\*\*2/"],
              {"model/params.py"}),
    # AC = -a_r omega^2 sin(theta) / g
    "AC": ([r"(omega|w)\*\*2\*(math\.|np\.)?sin(\([^)]*\))?/"],
           {"model/params.py"}),
    # lambda = c +- sqrt(c^2 - det): eq. 10's closed form for a 2 x 2 matrix
    "eigenvalues": ([r"\b(c\*c|c\*\*2|half\*\*2|\(tr[a-z]*/2(\.0)?\)\*\*2|tr[a-z]*\*\*2/4(\.0)?|"
                     r"tr[a-z]*\*\*2)-(4(\.0)?\*)?det"],
                    {"model/linear.py"}),
}


def code_text(path: Path) -> str:
    """The module's code without comments, strings or spaces."""
    kept = []
    for tok in tokenize.generate_tokens(io.StringIO(path.read_text()).readline):
        if tok.type in (tokenize.COMMENT, tokenize.STRING, tokenize.NL, tokenize.NEWLINE,
                        tokenize.INDENT, tokenize.DEDENT):
            continue
        kept.append(tok.string)
    return "".join(kept)


MODULES = {p.relative_to(PACKAGE).as_posix(): code_text(p) for p in PACKAGE.rglob("*.py")}


@pytest.mark.parametrize("formula", sorted(FORMULAS))
def test_a_formula_is_written_in_its_module_alone(formula):
    patterns, home = FORMULAS[formula]
    found = {name for name, text in MODULES.items()
             if any(re.search(p, text) for p in patterns)}
    assert found - home == set(), f"{formula} written again outside {sorted(home)}"
    assert found == home, f"{formula}: the patterns no longer find its definition"


@pytest.mark.parametrize("formula, spelling", [
    ("eq. 8", "cos_t = math.pi * (1 - alpha) / (1 + alpha) * g / (omega**2 * a)"),
    ("eq. 8", "a = math.cos(theta) * w**2 * a_r / (math.pi * g)"),
    ("Gamma", "gamma = a_r * omega ** 2 / g"),
    ("Gamma", "gamma = a_r * (2 * np.pi / tau) ** 2 / params.g"),
    ("AC", "ac = -a_r * omega**2 * np.sin(theta) / g"),
    ("eigenvalues", "lam = c + np.sqrt(c**2 - det)"),
    ("eigenvalues", "lam = tr / 2 + np.sqrt(tr**2 / 4 - det)"),
    ("eigenvalues", "disc = trace**2 - 4 * det"),
])
def test_the_patterns_catch_a_formula_written_again(tmp_path, formula, spelling):
    path = tmp_path / "module.py"
    path.write_text(spelling + "\n")
    assert any(re.search(p, code_text(path)) for p in FORMULAS[formula][0])
