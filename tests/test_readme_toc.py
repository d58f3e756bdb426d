"""The README's table of contents lists its sections, with anchors GitHub generates."""
from __future__ import annotations

from pathlib import Path

from vtoladapt.experiments.readme import TOC_BEGIN, TOC_END, heading_anchor, readme_block, readme_toc

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_toc_is_current():
    text = README.read_text()
    assert readme_block(text, TOC_BEGIN, TOC_END) == readme_toc(text), \
        "run: python -m vtoladapt.experiments.readme --toc README.md"


def test_anchors_follow_github():
    # GitHub: lower case, punctuation other than '-' and '_' dropped, each space a hyphen
    assert heading_anchor("What `make reproduce` produces") == "what-make-reproduce-produces"
    assert heading_anchor("Reinforcement-learning environment (Gymnasium)") == \
        "reinforcement-learning-environment-gymnasium"
    assert heading_anchor("When things go wrong: faults and divergence") == "when-things-go-wrong-faults-and-divergence"
    assert heading_anchor("The `l1` baseline: L1 adaptive control") == "the-l1-baseline-l1-adaptive-control"


def test_toc_skips_code_blocks_and_numbers_repeats():
    text = "# T\n\n## A b\n\n```sh\n## not a heading\n```\n\n### A b\n\n## A b\n"
    assert readme_toc(text) == "- [A b](#a-b)\n- [A b](#a-b-2)\n"
