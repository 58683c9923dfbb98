"""STOMP smooth noise: the finite-difference matrix, its covariance, and sampling."""

from __future__ import annotations

import pytest
import torch

from ebm_agent.stomp import StompNoise, finite_difference_matrix, smoothness_covariance


@pytest.mark.parametrize("terminal", [True, False])
@pytest.mark.parametrize("horizon", [1, 2, 3, 10, 20])
def test_matrix_rows_and_invertibility(horizon: int, terminal: bool) -> None:
    matrix = finite_difference_matrix(horizon, terminal_first_difference=terminal)
    assert matrix.shape == (horizon + 2, horizon)
    assert matrix.dtype == torch.float64
    # Rows 0..T-1: x_0, x_1 - 2 x_0, then second differences (a unit lower-triangular block).
    for row in range(horizon):
        expected = torch.zeros(horizon, dtype=torch.float64)
        for offset, value in enumerate((1.0, -2.0, 1.0)):
            if 0 <= row - offset < horizon:
                expected[row - offset] = value
        torch.testing.assert_close(matrix[row], expected)
    assert torch.all(matrix[horizon] == 0)  # the removed -2 x_{T-1} + x_{T-2} row
    last = torch.zeros(horizon, dtype=torch.float64)
    if terminal and horizon >= 2:
        last[horizon - 2], last[horizon - 1] = 1.0, -1.0  # the original's first difference x_{T-2} - x_{T-1}
    torch.testing.assert_close(matrix[horizon + 1], last)
    assert torch.linalg.matrix_rank(matrix.T @ matrix) == horizon


@pytest.mark.parametrize("terminal", [True, False])
def test_covariance_is_scaled_inverse_precision(terminal: bool) -> None:
    matrix = finite_difference_matrix(10, terminal)
    covariance = smoothness_covariance(10, scale=1e-5, terminal_first_difference=terminal)
    torch.testing.assert_close(covariance @ (matrix.T @ matrix), 1e-5 * torch.eye(10, dtype=torch.float64))
    torch.testing.assert_close(covariance, covariance.T, rtol=0, atol=0)


def test_std_matches_the_original_code() -> None:
    # reference/original_code.md §3: about 0.003 at t=1 growing to 0.033 at t=10 (T=10), 0.088 at t=20 (T=20).
    std_10 = smoothness_covariance(10).diagonal().sqrt()
    std_20 = smoothness_covariance(20).diagonal().sqrt()
    assert std_10[0].item() == pytest.approx(0.003, abs=0.0003)
    assert std_10[-1].item() == pytest.approx(0.033, abs=0.001)
    assert std_20[-1].item() == pytest.approx(0.088, abs=0.001)
    assert torch.all(std_10[1:] > std_10[:-1]), "the noise must be anchored at the start and loose at the end"
    # Without the terminal row the first step is exactly sqrt(c) and the end is looser.
    std_plain = smoothness_covariance(10, terminal_first_difference=False).diagonal().sqrt()
    assert std_plain[0].item() == pytest.approx(1e-5**0.5, rel=1e-9)
    assert std_plain[-1] > std_10[-1]


@pytest.mark.parametrize("terminal", [True, False])
def test_empirical_covariance_matches(terminal: bool) -> None:
    noise = StompNoise(8, scale=1e-5, terminal_first_difference=terminal, dtype=torch.float64)
    generator = torch.Generator().manual_seed(0)
    samples = noise.sample((40_000,), state_dim=3, generator=generator)  # [S, T, D]
    assert samples.shape == (40_000, 8, 3)
    per_dim = samples.permute(0, 2, 1).reshape(-1, 8)  # dims are independent copies: [S * D, T]
    empirical = per_dim.T @ per_dim / per_dim.shape[0]
    scale = noise.covariance.diagonal().max()
    assert (empirical - noise.covariance).abs().max() < 0.03 * scale
    # Different state dims are uncorrelated.
    correlation = torch.corrcoef(samples[:, -1, :].T)
    assert (correlation - torch.eye(3, dtype=torch.float64)).abs().max() < 0.03


def test_sample_shape_dtype_and_seed() -> None:
    noise = StompNoise(5)
    first = noise.sample((2, 7), state_dim=4, generator=torch.Generator().manual_seed(3))
    again = noise.sample((2, 7), state_dim=4, generator=torch.Generator().manual_seed(3))
    other = noise.sample((2, 7), state_dim=4, generator=torch.Generator().manual_seed(4))
    assert first.shape == (2, 7, 5, 4) and first.dtype == torch.float32
    assert torch.equal(first, again)
    assert not torch.equal(first, other)
    torch.testing.assert_close(noise.cholesky @ noise.cholesky.T, noise.covariance)
    assert torch.all(noise.cholesky.triu(1) == 0)


def test_bad_arguments_are_rejected() -> None:
    with pytest.raises(ValueError, match="horizon"):
        finite_difference_matrix(0)
    with pytest.raises(ValueError, match="scale"):
        smoothness_covariance(5, scale=0.0)
    with pytest.raises(ValueError, match="state_dim"):
        StompNoise(5).sample((2,), state_dim=0)
    with pytest.raises(TypeError, match="floating"):
        StompNoise(5, dtype=torch.int64)
