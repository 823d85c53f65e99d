"""A capture whose images follow another phase convention is refused with the import option that fixes it.

Synthetic: projector frames rendered with ``phase=pi`` (camera = projector, seeded noise), imported
with and without it; real: the SLMaster eye (Gray code) and heterodyne set imported without
``phase=pi`` (skipped cleanly without ``../shared/real-data``).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from realdata import REAL_DATA, needs_real_data

from processing.phase.convention import OffsetEstimate, gray_offset, heterodyne_offset
from processing.projection.patterns import pattern_image
from rig.cli import main
from rig.store.importer import parse_spec

SIZE = (480, 40)  # projector = camera, (width, height)


def _render(folder: Path, spec: str, seed: int = 0) -> Path:
    folder.mkdir(parents=True)
    rng = np.random.default_rng(seed)
    for index, pattern in enumerate(parse_spec(spec)):
        image = 20 + 200 * pattern_image(pattern, SIZE) + rng.normal(0, 2.0, (SIZE[1], SIZE[0]))
        cv2.imwrite(str(folder / f"{index}.png"), np.clip(np.rint(image), 0, 255).astype(np.uint8))
    return folder


def _process(capsys, folder: Path, spec: str, out: Path) -> tuple[int, str]:
    assert main(["import", str(folder), "--patterns", spec, "--projector-width", str(SIZE[0]), "-o", str(out)]) == 0
    capsys.readouterr()
    code = main(["process", str(out), "-o", str(out) + "-out", "-q"])
    return code, capsys.readouterr().err


@pytest.mark.parametrize(
    "rendered,imported",
    [
        ("sin:f=16,steps=4,phase=pi; gray:bits=5", "sin:f=16,steps=4; gray:bits=5"),  # complementary Gray code
        ("sin:f=16,steps=4,phase=pi; gray:bits=4", "sin:f=16,steps=4; gray:bits=4"),  # plain Gray code
        ("sin:f=24/20/17,steps=4,phase=pi", "sin:f=24/20/17,steps=4"),  # heterodyne (beats 4, 3 -> 1)
    ],
)
def test_wrong_phase_convention_is_refused_with_the_fix(capsys, tmp_path, rendered, imported) -> None:
    folder = _render(tmp_path / "images", rendered)
    code, err = _process(capsys, folder, imported, tmp_path / "wrong")
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 1 and len(lines) == 1 and "Traceback" not in err, err
    assert "phase convention" in lines[0] and "re-import with phase=pi" in lines[0]
    assert "phase=pi" in lines[0].split("--patterns (")[1]  # the corrected spec, ready to paste
    code, err = _process(capsys, folder, rendered, tmp_path / "right")
    assert code == 0, err  # the right convention passes (no false alarm)
    main(
        [
            "process",
            str(tmp_path / "wrong"),
            "-o",
            str(tmp_path / "forced"),
            "-q",
            "--param",
            "phase_convention_check=false",
        ]
    )
    assert "phase convention" not in capsys.readouterr().err  # the off switch processes (heterodyne: nothing valid)


def test_offset_estimates_on_ideal_phases() -> None:
    u = np.arange(SIZE[0]) + 0.5
    phi = np.tile(2 * np.pi * 16 * u / SIZE[0], (4, 1))
    stripes = np.tile(np.asarray((u * 32 / SIZE[0]).astype(int)), (4, 1))
    gray_plain = np.tile(np.asarray((u * 16 / SIZE[0]).astype(int)), (4, 1))
    for offset in (0.0, np.pi / 2, np.pi, -np.pi / 2):
        est = gray_offset(phi + offset, stripes, 5, 16)
        assert abs(np.angle(np.exp(1j * (est.offset - offset)))) < 0.05 and est.concentration > 0.6
        plain = gray_offset(phi + offset, gray_plain, 4, 16)
        assert abs(np.angle(np.exp(1j * (plain.offset - offset)))) < 0.15
        het = heterodyne_offset([phi * f / 16 + offset for f in (24, 20, 17)], [24, 20, 17])
        assert abs(np.angle(np.exp(1j * (het.offset - offset)))) < 1e-6 and het.concentration > 0.99
    assert not OffsetEstimate(0.1, 0.9, 10_000).suspicious()
    assert OffsetEstimate(3.1, 0.6, 10_000).suspicious() and not OffsetEstimate(3.1, 0.1, 10_000).suspicious()


@needs_real_data
@pytest.mark.parametrize(
    "folder,spec",
    [("slmaster-eye/L", "sin:f=32,steps=12; gray:bits=6"), ("slmaster-david-heterodyne", "sin:f=64/58/53,steps=4")],
)
def test_real_data_without_phase_pi_is_refused(capsys, tmp_path, folder, spec) -> None:
    out = tmp_path / "capture"
    assert (
        main(
            [
                "import",
                str(REAL_DATA / folder),
                "--patterns",
                spec,
                "--projector-width",
                "1920",
                "--downsample",
                "2",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert main(["process", str(out), "-o", str(tmp_path / "out"), "-q"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "phase convention" in err
    assert "re-import with phase=pi" in err
    assert not (tmp_path / "out").exists()
