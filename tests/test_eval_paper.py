"""``gngdt eval paper`` on a small trial count: report structure and a few robust figures."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from services.cli import main as gngdt_main
from services.evaluation.paper import (
    PAPER_TABLE2,
    PAPER_TABLE3,
    PaperSettings,
    separates_regions,
)

PAPER_TEXT = Path(__file__).resolve().parents[2] / "shared" / "paper" / "gng-dt-paper.md"
SCALES = ("1.0", "10.0", "0.1", "0.01")


def _published_rows(table_number: int) -> list[list[tuple[float, float]]]:
    """The 8 'scl = ...' rows of Table 2 or 3 in the paper's text: [GNG, GNG-W, GNG-DT] cells."""
    text = PAPER_TEXT.read_text(encoding="utf-8")
    section = text[text.index(f"**Table {table_number}.**") :]
    rows = []
    for line in section.splitlines():
        if line.startswith("<i>scl</i>"):
            cells = re.findall(r"([\d.]+) ± ([\d.]+)", line)
            rows.append([(float(m), float(s)) for m, s in cells])
        if len(rows) == 8:
            break
    return rows


@pytest.mark.parametrize(("number", "table"), [(2, PAPER_TABLE2), (3, PAPER_TABLE3)])
def test_embedded_tables_match_the_paper_text(number, table) -> None:
    if not PAPER_TEXT.is_file():
        pytest.skip(f"the paper's text is not at {PAPER_TEXT}")
    rows = _published_rows(number)
    scales = [1.0, 10.0, 0.1, 0.01]
    for offset, dataset in ((0, "Data1"), (4, "Data2")):
        for row, scale in zip(rows[offset : offset + 4], scales, strict=True):
            embedded = [table[dataset][m][scale] for m in ("GNG", "GNG-W", "GNG-DT")]
            assert embedded == row, (dataset, scale)


def test_separates_regions() -> None:
    truth = np.repeat([0, 1, 2, 3], 10)
    assert separates_regions(truth, truth + 7, 4)
    # one cluster mixing two regions half and half
    mixed = truth.copy()
    mixed[truth == 1] = 0
    assert not separates_regions(truth, mixed, 3)
    # unclustered points (-1) are left out; a 5th cluster makes the count wrong
    with_noise = truth.copy()
    with_noise[::10] = -1
    assert separates_regions(truth, with_noise, 4)
    assert not separates_regions(truth, np.where(np.arange(40) == 0, 9, truth), 4)


def test_settings_reject_bad_values() -> None:
    with pytest.raises(ValueError, match="trials"):
        PaperSettings(trials=0)
    with pytest.raises(ValueError, match="methods"):
        PaperSettings(methods=("SOM",))


@pytest.mark.timeout(300)
def test_eval_paper_small_run(tmp_path) -> None:
    out = tmp_path / "paper"
    argv = [
        "eval",
        "paper",
        "--trials",
        "1",
        "--steps",
        "20000",
        "--max-nodes",
        "40",
        "--data2-points",
        "20000",
        "--workers",
        "2",
        "--out",
        str(out),
        "--no-progress",
    ]
    assert gngdt_main(argv) == 0
    data = json.loads((out / "paper.json").read_text())
    markdown = (out / "paper.md").read_text()

    for heading in (
        "## Table 2",
        "## Table 3",
        "## Table 4",
        "## Figure 10",
        "## Topologies",
        "## Clusters per topology",
        "## The paper's findings, checked",
        "## Where our numbers differ",
    ):
        assert heading in markdown
    assert "20,000 steps" in markdown and "at most 40 nodes" in markdown
    assert "7.341 ± 0.022" in markdown  # a published cell beside ours

    assert len(data["trials"]) == 2 * 4 * 3
    assert all(r["steps"] == 20_000 and r["nodes"] == 40 for r in data["trials"])
    table2 = data["tables"]["table2"]
    for dataset in ("Data1", "Data2"):
        for method in ("GNG", "GNG-W", "GNG-DT"):
            assert set(table2[dataset][method]) == set(SCALES)
            for cell in table2[dataset][method].values():
                assert cell["ours"]["n"] == 1 and cell["ours"]["mean"] > 0
    assert table2["Data1"]["GNG-DT"]["1.0"]["paper"] == {"mean": 7.341, "std": 0.022}

    # GNG-DT chooses winners by position only: its error / scl is flat across scales
    for dataset in ("Data1", "Data2"):
        ratios = [data["tables"]["figure10"][dataset]["GNG-DT"][s]["ours"]["mean"] for s in SCALES]
        assert max(ratios) / min(ratios) < 1.1
    # ... and its colour topology splits Data1 into the four rectangles at every scale
    counts = data["tables"]["clusters"]["Data1"]["GNG-DT"]
    assert [counts[s]["col"]["per_trial"] for s in SCALES] == [[4]] * 4
    assert all(c["per_trial"] == [1] for c in [counts[s]["pos"] for s in SCALES])
    separated = data["tables"]["rectangles_separated"]["GNG-DT"]
    assert [separated[s]["separated"] for s in SCALES] == [1, 1, 1, 1]
    centre_errors = data["tables"]["table4"]["1.0"]
    assert all(0 <= centre_errors[c]["ours"]["mean"] < 75 for c in ("C1", "C2", "C3", "C4"))

    for plot in (
        "figure10_data1.png",
        "figure10_data2.png",
        "topologies_data1.png",
        "topologies_data2.png",
    ):
        assert (out / plot).stat().st_size > 5_000
        assert plot in markdown


def test_a_scale_the_paper_does_not_have_is_reported_without_a_paper_column(tmp_path) -> None:
    out = tmp_path / "paper"
    argv = ["eval", "paper", "--trials", "1", "--steps", "3000", "--max-nodes", "20",
            "--datasets", "Data1", "--scales", "1", "0.5", "--workers", "1",
            "--out", str(out), "--no-progress"]
    assert gngdt_main(argv) == 0
    findings = json.loads((out / "paper.json").read_text())["findings"]
    lowest = findings["Data1 scl=0.5: GNG-DT has the lowest position error"]
    assert "paper" not in lowest
    assert "paper" in findings["Data1 scl=1: GNG-DT has the lowest position error"]
