"""processing.concurrency: two steps side by side, results and errors as if run one after the other."""

from __future__ import annotations

import threading

import pytest

from processing import concurrency


def test_both_results_come_back_and_the_second_runs_on_another_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(concurrency, "THREADS", 2)
    first, second = concurrency.side_by_side(lambda: threading.get_ident(), lambda: threading.get_ident())
    assert first == threading.get_ident() and second != first


def test_one_thread_runs_both_here(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(concurrency, "THREADS", 1)
    here = threading.get_ident()
    assert concurrency.side_by_side(threading.get_ident, threading.get_ident) == (here, here)


def test_errors_are_raised_after_both_finished(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(concurrency, "THREADS", 2)
    finished = threading.Event()

    def slow() -> int:
        finished.wait(0.05)
        finished.set()
        return 1

    def fail() -> int:
        raise ValueError("first")

    with pytest.raises(ValueError, match="first"):
        concurrency.side_by_side(fail, slow)
    assert finished.is_set()  # the second step was not left running
    with pytest.raises(KeyError):
        concurrency.side_by_side(lambda: 0, lambda: {}["missing"])


def test_nested_calls_from_the_helper_thread_do_not_wait_on_themselves(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(concurrency, "THREADS", 2)
    inner = concurrency.side_by_side(lambda: 1, lambda: concurrency.side_by_side(lambda: 2, lambda: 3))
    assert inner == (1, (2, 3))


def test_on_threads_runs_the_task_here_and_on_kept_helpers() -> None:
    here = threading.get_ident()
    started = threading.Barrier(3, timeout=5)  # all three calls run at once, or this times out

    def task() -> threading.Thread:
        started.wait()
        return threading.current_thread()

    threads = concurrency.on_threads(task, 3)
    assert threads[0].ident == here and len({t.ident for t in threads}) == 3
    assert all(t.is_alive() for t in threads[1:])  # kept for the next call, not joined
    assert concurrency.on_threads(threading.get_ident, 1) == [here]


def test_on_threads_raises_after_every_call_finished() -> None:
    finished = threading.Event()

    def task() -> int:
        if threading.current_thread() is threading.main_thread():
            raise ValueError("here")
        finished.wait(0.05)
        finished.set()
        return 1

    with pytest.raises(ValueError, match="here"):
        concurrency.on_threads(task, 2)
    assert finished.is_set()
    with pytest.raises(KeyError):
        concurrency.on_threads(lambda: {}["missing"] if concurrency._on_helper() else 0, 2)


def test_on_threads_from_a_helper_runs_once_there(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(concurrency, "THREADS", 2)
    _, inner = concurrency.side_by_side(lambda: 0, lambda: concurrency.on_threads(threading.get_ident, 4))
    assert len(inner) == 1 and inner[0] != threading.get_ident()
