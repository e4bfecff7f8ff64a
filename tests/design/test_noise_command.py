"""The noise-driven command and the rate limit's equivalent gain (design.core.noise), against hand computation."""

import math

import numpy as np
import pytest

from design.core.compensator import Compensator
from design.core.errors import DesignInputError
from design.core.noise import disk_gain_floor, noise_command_sigma, saturation_gain, velocity_noise


def _static(k: float) -> Compensator:
    """u = k (y + w): a one-state compensator whose state does nothing."""
    return Compensator(np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)), np.array([[k]]), dt=0.05)


def test_the_command_s_sigma_is_the_hand_computed_one_on_a_first_order_loop():
    # x+ = 0.5 x + u, y = x, u = -0.3 (y + w), w ~ N(0, 0.1^2): x+ = 0.2 x - 0.03 w, so var x = 0.03^2 / (1 - 0.04)
    # and u = -0.3 x - 0.3 w with x independent of this sample's w: var u = 0.09 var x + 0.09 * 0.01
    a, b, c, d = np.array([[0.5]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[0.0]])
    var_x = 0.03 ** 2 / (1 - 0.2 ** 2)
    assert noise_command_sigma(_static(-0.3), a, b, c, d, [0.1]) == pytest.approx(math.sqrt(0.09 * var_x + 0.0009))
    # unstable closed loop (0.5 + 0.8 > 1): no stationary sigma
    assert noise_command_sigma(_static(0.8), a, b, c, d, [0.1]) == math.inf
    assert noise_command_sigma(_static(-0.3), a, b, c, d, [0.0]) == 0.0


def test_the_command_s_sigma_agrees_with_a_simulation():
    rng = np.random.default_rng(3)
    a = np.array([[0.9, 0.05], [0.0, 0.8]]); b = np.array([[0.0], [0.1]]); c = np.eye(2); d = np.zeros((2, 1))
    comp = Compensator(np.array([[0.5]]), np.array([[0.2, -0.1]]), np.array([[-1.0]]), np.array([[-2.0, -0.5]]),
                       dt=0.05)
    sig = np.array([0.02, 0.01])
    x, xc, us = np.zeros(2), np.zeros(1), []
    for _ in range(200_000):
        y = c @ x + sig * rng.standard_normal(2)
        u = comp.Cc @ xc + comp.Dc @ y
        x, xc = a @ x + b @ u, comp.Ac @ xc + comp.Bc @ y
        us.append(u[0])
    assert np.std(us[1000:]) == pytest.approx(noise_command_sigma(comp, a, b, c, d, sig), rel=0.02)


def test_saturation_gain_and_the_disk_margin_s_floor():
    assert saturation_gain(0.0, 0.3) == 1.0 and saturation_gain(math.inf, 0.3) == 0.0
    assert saturation_gain(0.3, 0.3) == pytest.approx(math.erf(1 / math.sqrt(2)))      # 0.683 at 1-sigma
    assert disk_gain_floor(0.6) == pytest.approx(1.4 / 2.6)
    assert velocity_noise(0.01, 0.002, 0.005, 2.0) == (0.005, 0.001, 0.005)
    with pytest.raises(DesignInputError, match="disk margin"):
        disk_gain_floor(2.0)
    with pytest.raises(DesignInputError, match="limit"):
        saturation_gain(0.1, 0.0)
    with pytest.raises(DesignInputError, match="speed"):
        velocity_noise(0.01, 0.002, 0.005, 0.0)
    with pytest.raises(DesignInputError, match="one per output"):
        noise_command_sigma(_static(-0.3), np.eye(1), np.eye(1), np.eye(1), np.zeros((1, 1)), [0.1, 0.2])
