"""Derivatives of the spectra: the simulators' capability, its conformance check, the core function's FD fallback."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from conftest import ROOT
from suspid import registry
from suspid.interfaces import DifferentiableSimulator
from suspid.method.jacobian import gauss_newton_information, spectra_jacobian
from suspid.testing import check_differentiable, sample_segments

SPECTRA = {"f_min_hz": 0.5, "f_max_hz": 20.0, "n_freqs": 60}


@pytest.fixture(scope="module")
def train():
    return registry.get("simulator", "exudyn-train")


@pytest.fixture(scope="module")
def segments():
    return sample_segments(2, length_m=900.0, speed_mps=83.3, seed=3)


def test_exudyn_train_derivatives_match_central_differences(train, segments):
    # suspension parameters, the model parameters the trust checks calibrate, and a mass (central difference
    # of the matrices: the wheel loads set the contact stiffness and Kalker's coefficients nonlinearly)
    names = ["k_sec_z", "c_sec_z", "k_prim_z", "c_sec_y", "c_yaw", "k_sec_z_s", "k_yaw_s", "kalker_scale",
             "conicity", "m_bogie"]
    errors = check_differentiable(train, {"solver": "frequency"}, segments, names=names, rtol=1e-4)
    assert set(errors) == set(names)


def test_geometry_and_time_solver_are_left_to_finite_differences(train):
    sim = train(solver="frequency")
    assert isinstance(sim, DifferentiableSimulator)
    assert sim.differentiable(["h_car", "k_sec_z", "a_bogie", "c_yaw"]) == ["k_sec_z", "c_yaw"]
    assert train(solver="time").differentiable(["k_sec_z"]) == []


def test_analytic_spectra_jacobian_equals_the_finite_difference_fallback(train, segments):
    """The core function on the built-in model: analytic where offered equals its own central FD fallback."""
    sim = train(solver="frequency")
    names = ["k_sec_z", "c_yaw", "conicity", "h_car"]       # h_car (geometry): FD inside the analytic call
    w = {"k_sec_z": 3.1e5, "c_yaw": 2.4e5}
    auto = spectra_jacobian(sim, w, names, segments, SPECTRA)
    fd = spectra_jacobian(sim, w, names, segments, SPECTRA, method="central")
    assert auto.methods == {"k_sec_z": "analytic", "c_yaw": "analytic", "conicity": "analytic", "h_car": "central"}
    assert auto.n_analytic_calls == 1 and auto.n_simulations == 2
    assert fd.n_simulations == 2 * len(names) + 1 and set(fd.methods.values()) == {"central"}
    assert auto.jacobian.shape == (2, len(sim.channels()), 60, 4)
    np.testing.assert_allclose(auto.y, fd.y, atol=1e-9)
    for k, name in enumerate(names):
        err = np.linalg.norm(auto.jacobian[..., k] - fd.jacobian[..., k]) / np.linalg.norm(fd.jacobian[..., k])
        assert err < 1e-4, (name, err)


def test_a_simulator_without_derivatives_gets_finite_differences(segments):
    """The plugin template's quarter car (no derivatives): forward and central differences through the executor."""
    sys.path.insert(0, str(ROOT / "examples" / "plugin-template" / "src"))
    try:
        from suspid_quartercar import QuarterCar
    finally:
        sys.path.pop(0)
    sim = QuarterCar(fs_hz=100.0)
    assert not isinstance(sim, DifferentiableSimulator)
    names = [p.name for p in sim.parameters()][:2]
    executor = registry.get("executor", "serial")()
    central = spectra_jacobian(sim, {}, names, segments, SPECTRA, executor=executor)
    forward = spectra_jacobian(sim, {}, names, segments, SPECTRA, executor=executor, fallback="forward",
                               rel_step=1e-5)
    assert set(central.methods.values()) == {"central"} and central.n_simulations == 2 * len(names) + 1
    assert forward.n_simulations == len(names) + 1
    rel = np.linalg.norm(central.jacobian - forward.jacobian) / np.linalg.norm(central.jacobian)
    assert rel < 1e-3


def test_gauss_newton_information_closed_form():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(3, 2, 4, 2))
    var = rng.uniform(0.5, 2.0, size=(2, 4))
    expected = sum(np.outer(J[i, k, j], J[i, k, j]) / var[k, j] for i in range(3) for k in range(2) for j in range(4))
    np.testing.assert_allclose(gauss_newton_information(J, var), expected, rtol=1e-12)
