"""RPCA solvers: exact recovery of planted low-rank + sparse matrices, fast path against the full-SVD reference."""

from __future__ import annotations

import numpy as np
import pytest

from processing.denoise.rpca import finite_median, robust_noise_sigma, rpca_adm, rpca_ialm
from processing.denoise.svd import SubspaceState, singular_value_threshold


def planted(
    n: int = 200, rank: int = 5, density: float = 0.05, seed: int = 1
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """D = L + S with L of ``rank`` (Gaussian factors) and ``density`` of S uniform in [-50, 50]."""
    rng = np.random.default_rng(seed)
    low = rng.standard_normal((n, rank)) @ rng.standard_normal((rank, n))
    sparse = np.zeros((n, n))
    where = rng.random((n, n)) < density
    sparse[where] = rng.uniform(-50.0, 50.0, int(where.sum()))
    return low + sparse, low, sparse


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.parametrize("svd", ["full", "auto", "partial"])
def test_ialm_recovers_planted_matrices(svd: str) -> None:
    d, low, sparse = planted()
    result = rpca_ialm(d, svd=svd)
    assert result.converged
    assert result.rank == 5
    assert relative(result.low_rank, low) < 1e-5
    assert relative(result.sparse, sparse) < 1e-5
    assert result.residual < 1e-7


def test_ialm_fast_path_agrees_with_full_svd_reference() -> None:
    d, _, _ = planted(seed=7)
    reference = rpca_ialm(d, svd="full")
    fast = rpca_ialm(d, svd="auto")
    assert relative(fast.low_rank, reference.low_rank) < 1e-6
    assert abs(fast.iterations - reference.iterations) <= 2


def test_ialm_float32_recovers_to_single_precision() -> None:
    d, low, _ = planted(seed=3)
    result = rpca_ialm(d.astype(np.float32))
    assert result.low_rank.dtype == np.float32
    assert relative(result.low_rank.astype(np.float64), low) < 1e-4


@pytest.mark.parametrize("svd", ["full", "auto"])
def test_adm_recovers_planted_matrices(svd: str) -> None:
    d, low, sparse = planted()
    result = rpca_adm(d, svd=svd)
    assert result.converged
    assert result.rank == 5
    assert relative(result.low_rank, low) < 1e-3
    assert relative(result.sparse, sparse) < 1e-3


def test_adm_t_weighting_equals_tau_form() -> None:
    # min t|E|_1 + (1-t)|K|_* has the minimiser of min |K|_* + t/(1-t) |E|_1.
    d, low, _ = planted(seed=5)
    t = 0.1
    weighted = rpca_adm(d, t=t, tol=1e-8)
    plain = rpca_adm(d, tau=t / (1 - t), beta=0.25 * d.size / np.abs(d).sum() / (1 - t), tol=1e-8)
    assert relative(weighted.low_rank, plain.low_rank) < 1e-4


def test_stable_mode_stops_at_noise_level_and_denoises() -> None:
    d, low, _ = planted(seed=2)
    sigma = 0.05
    noisy = d + np.random.default_rng(9).normal(0.0, sigma, d.shape)
    exact = rpca_ialm(noisy)
    # Random factors are not smooth along rows, so the robust estimate does not apply: give sigma.
    stable = rpca_ialm(noisy, stable=True, noise_sigma=sigma)
    assert stable.iterations < exact.iterations
    assert stable.rank == 5 < exact.rank
    # The stable low-rank part is closer to the clean L than the noisy data (error sigma * n).
    assert np.linalg.norm(stable.low_rank - low) < 0.5 * sigma * d.shape[0]
    assert relative(stable.low_rank, low) < relative(exact.low_rank, low)


def test_robust_noise_sigma_ignores_sparse_outliers() -> None:
    rng = np.random.default_rng(4)
    x = np.linspace(0, 20, 300)
    smooth = np.add.outer(np.sin(np.linspace(0, 3, 200)), x)
    noisy = smooth + rng.normal(0.0, 0.1, smooth.shape)
    noisy[rng.random(smooth.shape) < 0.02] += 2 * np.pi
    assert robust_noise_sigma(noisy) == pytest.approx(0.1, rel=0.1)


def test_partial_svt_matches_full_svt() -> None:
    rng = np.random.default_rng(11)
    x = rng.standard_normal((150, 8)) @ rng.standard_normal((8, 180)) * 10 + rng.standard_normal((150, 180)) * 0.1
    threshold = 5.0
    full, full_rank = singular_value_threshold(x, threshold, SubspaceState(), "full")
    state = SubspaceState(rank=2)  # predicted too low: the partial path must grow and still be exact
    partial, partial_rank = singular_value_threshold(x, threshold, state, "partial")
    assert partial_rank == full_rank == 8
    assert relative(partial, full) < 1e-8


def test_solvers_leave_the_blas_thread_count_alone() -> None:
    from threadpoolctl import threadpool_info

    def blas_threads() -> list[int]:
        return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]

    before = blas_threads()
    d = np.random.default_rng(3).standard_normal((64, 48))
    rpca_ialm(d, max_iter=3)
    rpca_adm(d, max_iter=3)
    assert blas_threads() == before


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"D": np.full((5, 5), np.nan)}, "D"),
        ({"D": np.ones(10)}, "D"),
        ({"D": np.ones((5, 5)), "tau": -1.0}, "tau"),
        ({"D": np.ones((5, 5)), "svd": "magic"}, "svd"),
        ({"D": np.ones((5, 5)), "rho": 1.0}, "rho"),
        ({"D": np.ones((5, 5)), "dtype": np.int32}, "dtype"),
    ],
)
def test_ialm_bad_input_names_the_argument(kwargs: dict, name: str) -> None:
    with pytest.raises(ValueError, match=f"^{name}:"):
        rpca_ialm(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"D": np.array([[1.0, np.inf], [0.0, 1.0]])}, "D"),
        ({"D": np.ones((5, 5)), "t": 1.5}, "t"),
        ({"D": np.ones((5, 5)), "beta": 0.0}, "beta"),
    ],
)
def test_adm_bad_input_names_the_argument(kwargs: dict, name: str) -> None:
    with pytest.raises(ValueError, match=f"^{name}:"):
        rpca_adm(**kwargs)


def test_zero_matrix_is_its_own_decomposition() -> None:
    result = rpca_ialm(np.zeros((4, 6)))
    assert result.converged and result.rank == 0 and not result.low_rank.any()


@pytest.mark.parametrize("size", [1, 2, 7, 10_000, 10_001])
def test_finite_median_equals_numpy_median_to_the_bit(size: int) -> None:
    values = np.random.default_rng(size).standard_normal(size) ** 2  # the squared misfits it is taken of
    assert finite_median(values) == float(np.median(values))
