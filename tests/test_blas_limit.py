"""rig.blas: the application's BLAS thread limit (threadpoolctl), set and restored (issue 9)."""

from __future__ import annotations

import pytest
from threadpoolctl import threadpool_info

from rig.blas import blas_threads, rpca_blas


def _counts() -> list[int]:
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


def test_limit_applies_inside_and_is_restored() -> None:
    before = _counts()
    assert before, "numpy's BLAS should be visible to threadpoolctl"
    with rpca_blas():
        assert all(count == 1 for count in _counts())
    assert _counts() == before


def test_none_leaves_blas_alone() -> None:
    before = _counts()
    with blas_threads(None):
        assert _counts() == before


@pytest.mark.parametrize("count", [0, -2, 1.5, True])
def test_bad_count_is_refused(count: object) -> None:
    with pytest.raises(ValueError, match="count: expected a positive number of threads"):
        with blas_threads(count):  # type: ignore[arg-type]
            pass
