"""Safety of the result directory: what is read, listed and replaced (issue 22: items 5, 8, 9, 14, 15).

Each test reproduces an attack or accident on a result directory and checks the promise of
docs/safety.md: regular files inside the directory only, staging names never taken for results,
an existing result never replaced without being asked, and every default name a valid name.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from cli_steps import assert_one_line, run
from console_client import BASE
from fastapi.testclient import TestClient

from rig import api
from rig.config import load_config
from rig.console.app import create_app
from rig.console.datadir import DataDir
from rig.errors import OutputError, RigError
from rig.store import results


@pytest.fixture
def data_with_result(tmp_path: Path, small_capture) -> Path:
    """DATA/ of a console with one processed result, DATA/results/r1."""
    result = api.process(small_capture.capture, small_capture.calibration, api.ProcessOptions(correction="none"))
    data = tmp_path / "data"
    DataDir(data)
    results.write_result(result, data / "results" / "r1")
    return data


@pytest.fixture
def console_on(simulated_rig_toml: Callable[..., str], tmp_path: Path) -> Callable[[Path], TestClient]:
    clients: list[TestClient] = []
    rig_toml = tmp_path / "rig.toml"
    rig_toml.write_text(simulated_rig_toml((456, 570), (160, 120), 35.0))

    def open_console(data: Path) -> TestClient:
        client = TestClient(create_app(load_config(rig_toml), data), base_url=BASE)
        clients.append(client.__enter__())
        return client

    yield open_console  # type: ignore[misc]
    for client in clients:
        client.__exit__(None, None, None)


def _quick(call: Callable[[], object], seconds: float = 10.0) -> object:
    """Call and check it came back in time (a FIFO opened for reading without a writer never returns)."""
    started = time.monotonic()
    value = call()
    assert time.monotonic() - started < seconds
    return value


# 8. a FIFO in a result folder: refused at once, the server keeps answering -----------------------


@pytest.mark.parametrize("file", [results.MASK, results.HEIGHT, results.REPORT, results.POINTS])
def test_a_fifo_in_a_result_is_refused_not_waited_for(data_with_result, console_on, file) -> None:
    folder = data_with_result / "results" / "r1"
    (folder / file).unlink()
    os.mkfifo(folder / file)
    with pytest.raises(OutputError, match="expected a regular file, found a FIFO"):
        _quick(lambda: results.read_result(folder))
    console = console_on(data_with_result)
    for _ in range(3):  # repeated requests used to pile up blocked threads until nothing answered
        response = _quick(lambda: console.get("/api/results/r1"))
        assert response.status_code in (400, 404, 409, 422)
        assert "FIFO" in response.json()["error"] or file == results.REPORT  # no report: "not found"
    assert _quick(lambda: console.get("/api/status")).status_code == 200


# 9. a file of a result folder linking outside: not followed -------------------------------------


def test_a_linked_file_in_a_result_is_not_followed(data_with_result, console_on, tmp_path) -> None:
    folder = data_with_result / "results" / "r1"
    secret = tmp_path / "outside" / "height.npy"
    secret.parent.mkdir()
    np.save(secret, np.full(np.load(folder / results.HEIGHT).shape, 1234.0, np.float32))
    (folder / results.HEIGHT).unlink()
    (folder / results.HEIGHT).symlink_to(secret)
    with pytest.raises(OutputError, match="symbolic link"):
        results.read_result(folder)
    with pytest.raises(OutputError, match="symbolic link"):
        results.result_file(folder, results.HEIGHT)
    assert results.result_file(folder, results.POINTS) == folder / results.POINTS  # its own files are served
    console = console_on(data_with_result)
    for route in ("/api/results/r1", "/api/results/r1/values.f32", "/api/results/r1/map.png"):
        response = console.get(route)
        assert response.status_code >= 400 and b"1234" not in response.content


# 5. staging names (an interrupted commit) are never results ---------------------------------------


def test_a_staging_result_is_never_listed_or_read(data_with_result, console_on) -> None:
    root = data_with_result / "results"
    staged = root / "r2.incomplete-abcd1234"  # what a kill during the commit leaves: a whole result
    os.rename(root / "r1", staged)
    assert results.list_results(root) == []
    assert not results.is_result(staged)
    with pytest.raises(OutputError, match="never committed"):
        results.read_result(staged)
    console = console_on(data_with_result)
    assert console.get("/api/results").json()["results"] == []
    assert console.get(f"/api/results/{staged.name}").status_code >= 400
    os.rename(staged, root / "r1")
    assert results.list_results(root) == ["r1"]
    assert [r["name"] for r in console.get("/api/results").json()["results"]] == ["r1"]


# 14. an existing result is replaced only when asked ----------------------------------------------


def test_rig_process_does_not_replace_its_default_output_unasked(capsys, small_capture) -> None:
    capture, calibration = small_capture.capture, small_capture.calibration
    assert run(capsys, "process", capture, "--calibration", calibration, "-q")[0] == 0
    out = results.default_output(capture)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert "height.npy" in before
    code, err = run(capsys, "process", capture, "-q")  # without a calibration: would drop height and points
    assert_one_line(code, err, str(out), "already exists", "--overwrite")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert run(capsys, "process", capture, "-q", "--overwrite")[0] == 0
    assert not (out / "height.npy").exists() and (out / "wrapped.npy").exists()


def test_the_store_refuses_to_replace_with_its_own_error(data_with_result, small_capture) -> None:
    result = api.process(small_capture.capture, options=api.ProcessOptions(correction="none"))
    target = data_with_result / "results" / "r1"
    before = (target / results.MASK).read_bytes()
    with pytest.raises(results.ResultExistsError, match="already exists") as caught:
        results.write_result(result, target)
    assert isinstance(caught.value, RigError)  # one line in the CLI; the console can answer 409
    assert (target / results.MASK).read_bytes() == before
    results.write_result(result, target, overwrite=True)
    assert (target / results.WRAPPED).is_file() and not (target / results.HEIGHT).exists()


# 15. long capture names: the default result name is a valid name ----------------------------------


def test_long_capture_names_get_valid_distinct_default_result_names(tmp_path) -> None:
    first, second = "a" * 250 + "-one", "a" * 250 + "-two"
    names = [results.default_output(tmp_path / n).name for n in (first, second, first)]
    assert all(len(n.encode()) <= results.NAME_LIMIT and n.endswith("-processed") for n in names)
    assert names[0] == names[2] and names[0] != names[1]  # deterministic, and distinct for distinct captures
    assert results.default_output(tmp_path / "part").name == "part-processed"  # short names unchanged
    data = DataDir(tmp_path / "data")
    long_capture = "c" * 100  # the longest name the console accepts
    name = data.new_name("results", f"{long_capture}-auto")
    assert data.path("results", name).name == name  # the console accepts its own default name


def test_rig_process_of_a_long_named_capture_writes_its_default_output(capsys, small_capture) -> None:
    long_name = small_capture.capture.with_name("x" * 250)
    os.rename(small_capture.capture, long_name)
    code, err = run(capsys, "process", long_name, "-q")
    assert code == 0, err
    out = results.default_output(long_name)
    assert out.parent == long_name.parent and (out / results.REPORT).is_file()
