"""The three-point second difference behind the intervals' curvature (``suspid.workflows.analysis``)."""

import numpy as np

from suspid.workflows.analysis import second_difference


def test_a_quadratic_curvature_is_exact_with_unequal_steps():
    """f(u) = Σ a_k u_k² + b_k u_k + c: d²f/du_k² = 2 a_k exactly, whatever the steps on either side (a box
    clips them), for scalar values and for values with more axes (per channel)."""
    a, b, u = np.array([-3.0, 0.5, 7.0]), np.array([1.0, -2.0, 0.25]), np.array([0.3, 0.9, 0.1])
    h_plus, h_minus = np.array([0.05, 0.1, 0.01]), np.array([0.02, 0.1, 0.04])
    f = lambda x: float(np.sum(a * x ** 2 + b * x)) + 4.0  # noqa: E731
    eye = np.eye(3)
    fp = np.array([f(u + h_plus[k] * eye[k]) for k in range(3)])
    fm = np.array([f(u - h_minus[k] * eye[k]) for k in range(3)])
    assert np.allclose(second_difference(f(u), fp, fm, h_plus, h_minus), 2 * a, rtol=1e-9, atol=1e-9)
    scale = np.array([1.0, -2.0])                        # two channels: f times each
    out = second_difference(f(u) * scale, fp[:, None] * scale, fm[:, None] * scale, h_plus, h_minus)
    assert out.shape == (3, 2) and np.allclose(out, 2 * a[:, None] * scale, rtol=1e-9, atol=1e-9)
