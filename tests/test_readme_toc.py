"""The README's table of contents lists its sections, with anchors GitHub generates; the generators
write the site's result pages and the README's headline."""
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


def test_the_generators_write_the_site_page_and_the_readme_headline(tmp_path):
    """``python -m vtoladapt.experiments.readme METRICS PAGE`` (and the envelope's tool) on a site
    page: the page's block, the README's headline and the copy in the repository's docs/ folder."""
    import json
    import shutil

    from vtoladapt.experiments import envelope_readme
    from vtoladapt.experiments import readme as tool

    repo = Path(__file__).resolve().parents[1]
    page = tmp_path / "docs" / "explanation" / "results.md"
    env_page = tmp_path / "docs" / "explanation" / "envelope.md"
    page.parent.mkdir(parents=True)
    page.write_text(f"# Results\n{tool.BEGIN}\nold\n{tool.END}\n")
    env_page.write_text(f"# Envelope\n{envelope_readme.BEGIN}\nold\n{envelope_readme.END}\n")
    front = (f"# x\n{tool.HEADLINE_BEGIN}\nold\n{tool.HEADLINE_END}\n"
             f"{envelope_readme.HEADLINE_BEGIN}\nold\n{envelope_readme.HEADLINE_END}\n")
    (tmp_path / "README.md").write_text(front)
    metrics_src = tmp_path / "metrics.json"
    shutil.copyfile(repo / "docs" / "reproduce_metrics.json", metrics_src)
    summary_src = tmp_path / "out" / "summary.json"
    summary_src.parent.mkdir()
    shutil.copyfile(repo / "docs" / "envelope_summary.json", summary_src)

    tool.update_readme(metrics_src, page)
    envelope_readme.update_readme(summary_src, env_page)

    metrics = json.loads(metrics_src.read_text())
    summary = json.loads(summary_src.read_text())
    assert readme_block(page.read_text()) == tool.readme_tables(metrics)
    assert readme_block(env_page.read_text(), envelope_readme.BEGIN, envelope_readme.END) == \
        envelope_readme.envelope_tables(summary).strip("\n") + "\n"
    text = (tmp_path / "README.md").read_text()
    assert readme_block(text, tool.HEADLINE_BEGIN, tool.HEADLINE_END) == tool.readme_headline(metrics)
    assert readme_block(text, envelope_readme.HEADLINE_BEGIN, envelope_readme.HEADLINE_END) == \
        envelope_readme.envelope_headline(summary).strip("\n") + "\n"
    # the copies go to the repository's docs/, not beside the page
    assert json.loads((tmp_path / "docs" / "reproduce_metrics.json").read_text()) == metrics
    assert json.loads((tmp_path / "docs" / "envelope_summary.json").read_text()) == summary
    assert not (page.parent / "docs").exists()
