"""Derivatives of the spectra: the simulators' capability, its conformance check, the core function's FD fallback."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from conftest import ROOT
from suspid import registry
from suspid.interfaces import DifferentiableSimulator
from suspid.method.jacobian import gauss_newton_information, linearised_shift
from suspid.workflows.jacobian import spectra_jacobian
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


class _PowerLawSpectra:
    """A closed-form model: y_i = 10 log10(x_1^a_i x_2^b_i) + c_i dB, J = -mean (y - y_target)²: maximum at x_target."""

    def __init__(self, target):
        rng = np.random.default_rng(1)
        self.A = rng.normal(size=(6, 2, 5, 2))
        self.c = rng.normal(size=(6, 2, 5))
        self.target = self.y(np.asarray(target, float))
        self.n_jacobians = 0

    def y(self, x):
        return 10 * np.log10(np.exp(self.A @ np.log(x))) + self.c

    def jacobian(self, x):
        self.n_jacobians += 1
        return self.y(x), 10 / np.log(10) * self.A / np.asarray(x, float)

    def objective(self, y_sim):
        return -float(np.mean((y_sim - self.target) ** 2))


def test_gauss_newton_finds_the_maximum_of_a_closed_form_model_in_a_few_steps():
    from suspid.interfaces import SpectraModel
    from suspid.optimize.design import DesignOptions

    SpectraModel.register(_PowerLawSpectra)
    cls = registry.get("optimizer", "gauss-newton")
    target = np.array([2.0e5, 3.5e4])
    model = _PowerLawSpectra(target)
    opt = cls(np.array([[1e5, 6e5], [1e4, 6e4]]), budget=30, seed=3, design=DesignOptions(n_initial=6))
    opt.spectra_model = model
    while not opt.done:
        X = opt.ask()
        if X.size == 0:
            break
        opt.tell(X, [model.objective(model.y(x)) for x in X])
    res = opt.result()
    np.testing.assert_allclose(res.x_opt, target, rtol=1e-3)
    assert res.n_initial == 6 and res.n_evaluations <= 12          # exact in log w: one or two steps
    assert model.n_jacobians <= res.n_evaluations - res.n_initial + 1


@pytest.mark.slow
@pytest.mark.parametrize("preset", ["conventional-hs", "tgv-articulated"])
def test_every_parameter_of_the_presets_matches_central_differences(train, preset):
    """The acceptance of the analytic Jacobian: every parameter exudyn-train differentiates, both presets the
    quickstart and the Table 1 analogue use, to 1e-4 relative (2-norm over channels and samples)."""
    sim = train(solver="frequency", vehicle=preset)
    names = sim.differentiable([p.name for p in sim.parameters()])
    assert len(names) >= 30
    segments = sample_segments(1, length_m=700.0, speed_mps=83.3, seed=5)
    errors = check_differentiable(train, {"solver": "frequency", "vehicle": preset}, segments, names=names,
                                  rtol=1e-4)
    assert set(errors) == set(names)


def test_grouped_matrix_derivatives_equal_the_one_by_one_ones(train):
    """After the first call, parameters with disjoint sparsity patterns share a linearisation: the same
    matrices, bit for bit, at another point, for a fraction of the linearisations."""
    from suspid.plugins.simulators.exudyn_train import sensitivity as S
    from suspid.plugins.simulators.exudyn_train.model import TimeFeatures

    sim = train(solver="frequency")
    names = sim.differentiable([p.name for p in sim.parameters()])
    v0 = sim.values({})
    model = sim._model(v0, 83.3, TimeFeatures())
    S._point_derivatives(model, v0, 83.3, names, model.linear_system())           # learns the patterns
    groups = S._groups(names, S._PATTERNS[model][tuple(names)])
    assert len(groups) <= len(names) // 2
    values = sim.values({"k_sec_z": 2.8e5, "c_sec_z": 1.4e4, "c_yaw": 2.1e5, "m_car": 5.0e4, "conicity": 0.2})
    model.update(values, 83.3)
    base = model.linear_system()
    grouped = S._point_derivatives(model, values, 83.3, names, base)
    single = [S._single(model, values, 83.3, n, base) for n in names]
    for n, a, b in zip(names, grouped, single):
        for f in ("dM", "dK", "dD", "dG"):
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f"{n} {f}")


@pytest.mark.parametrize("preset", ["conventional-hs", "tgv-articulated"])
def test_point_independent_matrix_derivatives_are_the_same_everywhere(train, preset):
    """The structure the kept matrix derivatives rest on: the kept kinds' derivatives are the same (to rounding)
    at a point where every differentiable parameter moved by up to 10 %, a mass's and the conicity's are not;
    and every derivative is the same where only the kept kinds moved."""
    from suspid.plugins.simulators.exudyn_train import sensitivity as S
    from suspid.plugins.simulators.exudyn_train.model import TimeFeatures

    sim = train(solver="frequency", vehicle=preset)
    names = sim.differentiable([p.name for p in sim.parameters()])
    kept = [n for n in names if S.kind_of(n) in S.POINT_INDEPENDENT]
    assert len(kept) >= 20 and "m_car" in names and "m_car" not in kept
    v0 = sim.values({})
    rng = np.random.default_rng(1)
    v1 = {**v0, **{n: v0[n] * (1 + 0.1 * rng.uniform(-1, 1)) for n in names}}
    model = sim._model(v0, 83.3, TimeFeatures())

    def derivatives(values, which):
        model.update(values, 83.3)
        base = model.linear_system()
        return [S._single(model, values, 83.3, n, base) for n in which]

    def rel(a, b):
        return max(float(np.max(np.abs(getattr(a, f) - getattr(b, f)))) / float(np.max(np.abs(getattr(a, f))))
                   for f in ("dM", "dK", "dD", "dG") if np.any(getattr(a, f)))

    at_v0 = derivatives(v0, names)
    for n, a, b in zip(names, at_v0, derivatives(v1, names)):
        if n in kept:
            assert rel(a, b) < 1e-7, (n, rel(a, b))
        elif n in ("m_car", "conicity"):
            assert rel(a, b) > 1e-3, n
    # the others' derivatives depend on the others alone: the same where only the kept kinds moved
    v2 = {**v0, **{n: v1[n] for n in kept}}
    for n, a, b in zip(names, at_v0, derivatives(v2, names)):
        assert rel(a, b) < 1e-7, (n, rel(a, b))


def test_linearised_shift_is_the_refit_of_a_linear_model():
    rng = np.random.default_rng(2)
    A, B = rng.normal(size=(4, 3, 5, 2)), rng.normal(size=(4, 3, 5, 1))
    var = rng.uniform(0.5, 2.0, size=(3, 5))
    w_true, theta_true, dtheta = np.array([1.0, -2.0]), np.array([0.5]), np.array([0.3])
    data = A @ w_true + B @ theta_true
    # weighted least squares with θ held at θ_true + Δθ
    s = np.sqrt(1 / np.broadcast_to(var, (4, 3, 5))).reshape(-1)
    rhs = (data - B @ (theta_true + dtheta)).reshape(-1) * s
    w_fit = np.linalg.lstsq(A.reshape(-1, 2) * s[:, None], rhs, rcond=None)[0]
    np.testing.assert_allclose(w_fit - w_true, linearised_shift(A, B, var) @ dtheta, atol=1e-12)


def test_an_undeclared_parameter_is_a_one_line_error(train, segments):
    from suspid.errors import SuspidError

    with pytest.raises(SuspidError, match="'no_such' not declared|no_such.* not declared"):
        spectra_jacobian(train(solver="frequency"), {}, ["k_sec_z", "no_such"], segments, SPECTRA)


@pytest.mark.parametrize("window,detrend", [("boxcar", "mean"), ("boxcar", "linear"), ("hann", "none"),
                                            ("hann", "mean")])
def test_record_spectrum_derivatives_match_differences_of_the_spectrum(window, detrend):
    """Y's derivative along given record derivatives (double and single precision) against central differences
    of Y itself, for every window and detrend (the compiled cell sums and the numpy reference alike)."""
    from suspid.method import spectra as SP

    rng = np.random.default_rng(4)
    fs, n_t = 100.0, 1000
    a = rng.standard_normal((3, n_t)) + 0.3
    d = rng.standard_normal((2, 3, n_t))
    opt = {"f_min_hz": 0.5, "f_max_hz": 20.0, "n_freqs": 40, "window": window, "detrend": detrend}
    y, dy = SP.record_spectrum_derivatives(a, d, fs, opt)
    _, dy32 = SP.record_spectrum_derivatives(a, d.astype(np.float32), fs, opt)
    h = 1e-6
    for k in range(2):
        fd = (SP.record_spectrum(a + h * d[k], fs, opt) - SP.record_spectrum(a - h * d[k], fs, opt)) / (2 * h)
        np.testing.assert_allclose(dy[k], fd, rtol=1e-5, atol=1e-6 * np.max(np.abs(fd)))
        np.testing.assert_allclose(dy32[k], fd, rtol=1e-3, atol=1e-4 * np.max(np.abs(fd)))
    opt_ = SP.parse_options(SP.SpectraOptions, opt, "spectra")
    _, mean, a_hat, start, stop = SP._record_power(a, fs, opt_)
    prepared = SP._prepare(d.reshape(-1, n_t), opt_) if (window, detrend) != ("boxcar", "mean") else d
    raw = np.fft.rfft(prepared, axis=-1).reshape(2, 3, -1)
    ref = np.empty_like(dy)
    SP._cell_derivatives_numpy(a_hat, raw, start, stop, mean, 1.0 / (fs * np.sqrt(n_t / fs)), ref)
    np.testing.assert_allclose(dy, ref, rtol=1e-10, atol=1e-12 * np.max(np.abs(ref)))


def test_compiled_loops_equal_their_numpy_references():
    """The receptance derivatives' compiled contraction and the records' products against the numpy forms
    used without numba."""
    from suspid.plugins.simulators.exudyn_train import sensitivity as S

    rng = np.random.default_rng(2)

    def cplx(*shape):
        return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)

    O_t, W = cplx(7, 4, 16), cplx(9, 3, 16)
    stack_rows, offsets = rng.integers(0, 7, 9), np.array([0, 2, 2, 6, 9])
    a = cplx(4, 3, 4, 40)
    b = a.copy()
    S._contract(O_t, W, stack_rows, offsets, a, 5)
    S._contract_numpy(O_t, W, stack_rows, offsets, b, 5)
    np.testing.assert_allclose(a, b, rtol=1e-12)
    dH, U = cplx(5, 3, 4, 33).astype(np.complex64), cplx(3, 33).astype(np.complex64)
    x, y = np.empty((5, 4, 33), np.complex64), np.empty((5, 4, 33), np.complex64)
    S._combine(dH, U, x)
    S._combine_numpy(dH, U, y)
    np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-5)


def test_kept_matrix_derivatives_give_a_fresh_simulators_jacobian(train):
    """After a Jacobian at one point, the one at another point (suspension rates moved, then a mass too) equals
    that of a fresh simulator there: what is kept between calls does not change the derivatives."""
    sim = train(solver="frequency")
    names = sim.differentiable([p.name for p in sim.parameters()])
    segs = sample_segments(1, length_m=300.0, speed_mps=83.3, seed=7)
    sim.simulate_jacobian({"k_sec_z": 2.9e5, "c_yaw": 2.2e5}, segs, names)
    for w in ({"k_sec_z": 3.2e5, "c_yaw": 2.6e5, "k_prim_z": 1.3e6},
              {"k_sec_z": 3.2e5, "c_yaw": 2.6e5, "m_car": 4.6e4}):
        (_, kept), = sim.simulate_jacobian(w, segs, names)
        (_, fresh), = train(solver="frequency").simulate_jacobian(w, segs, names)
        for k, n in enumerate(names):
            err = np.linalg.norm(kept[k] - fresh[k]) / np.linalg.norm(fresh[k])
            assert err < 1e-5, (w, n, err)
