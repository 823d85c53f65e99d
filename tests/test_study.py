"""`rig study --quick`: the reproduction study's machinery on small images, and its numbers' consistency."""

import csv
import re
from collections import defaultdict

import numpy as np
import pytest

from rig.cli import main
from rig.errors import ConfigError
from rig.study.experiments import METHODS, StudyConfig

FIGURES = [
    "table41_phase_maps.png",
    "table41_cross_section.png",
    "t_sweep_mse.png",
    "t_sweep_errors.png",
    "nmse_vs_snr.png",
    "denoise_cross_section.png",
    "denoise_heights.png",
    "isolated_phase_maps.png",
    "single_shot.png",
]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("study")
    assert main(["study", "--quick", "--seeds", "2", "-o", str(out)]) == 0
    with (out / "study.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    return out, rows


def _values(rows, experiment, metric, **keys):
    return [
        float(r["value"])
        for r in rows
        if r["experiment"] == experiment and r["metric"] == metric and all(r[k] == str(v) for k, v in keys.items())
    ]


def test_writes_report_csv_and_figures(study):
    out, rows = study
    report = (out / "README.md").read_text()
    for name in FIGURES:
        assert (out / name).stat().st_size > 1000, name
        assert f"]({name})" in report
    for heading in ("Table 4.1", "Ch. 2.4", "Ch. 3.3.2", "Fig. 4.5", "Ch. 4.3.1", "Ch. 2.3"):
        assert heading in report
    # The thesis' figures stand beside ours.
    for thesis_value in ("0.3893", "0.2959", "0.0057", "0.0081", "0.0199", "0.6786"):
        assert thesis_value in report
    assert {r["experiment"] for r in rows} == {
        "table-4.1",
        "denoise",
        "t-sweep",
        "snr-sweep",
        "isolated",
        "single-shot",
    }


def test_table_4_1_is_internally_consistent(study):
    out, rows = study
    for seed in (0, 1):
        nmse = {key: _values(rows, "table-4.1", "nmse_h", method=key, seed=seed)[0] for key in METHODS}
        errors = {key: _values(rows, "table-4.1", "order_errors", method=key, seed=seed)[0] for key in METHODS}
        # True orders can only help, and leave no order error.
        assert nmse["oracle"] <= nmse["none"]
        assert errors["oracle"] == 0
        # 15 dB leaves order errors to correct, and the thesis' ch. 4 method removes most of the damage.
        assert errors["none"] > 0
        assert nmse["rpca-phase"] < 0.1 * nmse["none"]
        assert nmse["auto"] < 0.1 * nmse["none"]
        # Post-processing only removes misalignments of ch. 3's RPCA.
        assert errors["rpca-orders"] <= errors["rpca-orders-nopost"]
    # The report's median equals the CSV's.
    report = (out / "README.md").read_text()
    median_none = np.median(_values(rows, "table-4.1", "nmse_h", method="none"))
    line = next(row for row in report.splitlines() if row.startswith("| no correction | 0.3893"))
    assert re.search(rf"\| {median_none:.4f} \(", line)


def test_sweeps_and_single_shot_are_consistent(study):
    _, rows = study
    # More noise, more wrong orders before correction.
    assert (
        _values(rows, "t-sweep", "order_errors", scene="hemisphere", snr_db=10.0, t="none")[0]
        > _values(rows, "t-sweep", "order_errors", scene="hemisphere", snr_db=15.0, t="none")[0]
    )
    none_by_snr = [_values(rows, "snr-sweep", "nmse_h", method="none", snr_db=s)[0] for s in (10.0, 15.0, 25.0)]
    assert none_by_snr[0] > none_by_snr[1] > none_by_snr[2]
    for scene in ("hemisphere", "two-hemispheres"):
        exact = _values(rows, "single-shot", "exact_voted", scene=scene, method="rpca")
        assert len(exact) == 2 and min(exact) > 0.85
        assert all(0 < v <= 1 for v in _values(rows, "single-shot", "valid_fraction", scene=scene, method="rpca"))
    # Denoising reduces the two-frequency unwrapping errors of the double hemisphere.
    raw = defaultdict(list)
    for method in ("raw", "rpca-denoised"):
        raw[method] = _values(rows, "denoise", "order_errors", case="two-freq-two-hemispheres", method=method)
    assert np.median(raw["rpca-denoised"]) < np.median(raw["raw"])


def test_bad_configuration_is_refused():
    with pytest.raises(ConfigError, match="size"):
        StudyConfig(size=16)
    with pytest.raises(SystemExit):
        main(["study", "--seeds", "0"])
