"""Parameter table of the built-in high-speed car, each value with its source.

Every physical quantity the model uses is a :class:`VehicleParameter`: name,
SI unit, nominal value, admissible bounds (used when the parameter is
identified), description and **source**. Any of them can be identified by
naming it under ``parameters:`` in a config, or given another nominal value
through the simulator option ``vehicle: {name: value}``.

The car ("TGV-class"): no public TGV parameter set exists
(``shared/reference/railway-data.md`` §1). The default car is a 320 km/h
passenger car on two conventional bogies with 0.92 m wheels, built from

- the masses, inertias, geometry, primary suspension and secondary springs
  of the **Manchester Benchmark Vehicle 1** (Iwnicki, Vehicle System
  Dynamics 30 (1998) 295-313, values as cited by public code, see
  railway-data.md §1; the paper itself was not read);
- **assumptions** where that source is silent (heights of the secondary
  suspension and of the yaw dampers, yaw damper spacing), marked below;
- the primary longitudinal stiffness of the **CRH380A-like** high-speed set
  (railway-data.md §1): the Manchester coach's 31 MN/m makes this car hunt;
- **stability tuning** for 320 km/h (the Manchester coach with linear creep
  hunts at 83 m/s for conicity 0.15, railway-data.md §1): the equivalent
  conicity (0.25), the yaw damper rate (800 kN s/m) and the lateral damper
  rate (16 kN s/m per side) were chosen with the eigenvalues of this model so
  that every mode is damped from 20 to 400 km/h (least damping ratio 0.125 at
  320 km/h, the carbody's lateral mode), at every corner of the default
  identification box, and with creep coefficients down to half of Kalker's
  (creep saturation lowers them in the time solver). See
  ``tests/test_exudyn_train.py``.

Conventions: x forward, y to the left, z up (right-handed); "per axlebox",
"per side" and "per damper" say how many elements share a value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

GRAVITY = 9.81
"""Gravitational acceleration, m/s^2."""

MANCHESTER = "Manchester Benchmark Vehicle 1 (Iwnicki 1998), as cited in railway-data.md §1"
ASSUMED = "assumption (typical value; not in the cited sources)"
CRH = "CRH380A-like high-speed set (railway-data.md §1; origin not confirmed)"
TUNED = "chosen for stability at 320 km/h with this model's eigenvalues (railway-data.md §1 warns)"


@dataclass(frozen=True)
class VehicleParameter:
    """One model parameter: value, admissible interval and where the value comes from."""

    name: str
    unit: str
    nominal: float
    lower: float
    upper: float
    description: str
    source: str


def _p(name: str, unit: str, nominal: float, lower: float, upper: float, description: str,
       source: str) -> VehicleParameter:
    return VehicleParameter(name, unit, float(nominal), float(lower), float(upper), description, source)


PARAMETERS: tuple[VehicleParameter, ...] = (
    # --- carbody -----------------------------------------------------------------------------------
    _p("m_car", "kg", 32000, 24000, 48000, "carbody mass", MANCHESTER),
    _p("I_car_x", "kg m^2", 56.8e3, 40e3, 90e3, "carbody roll inertia about its centre of mass", MANCHESTER),
    _p("I_car_y", "kg m^2", 1.97e6, 1.4e6, 2.8e6, "carbody pitch inertia", MANCHESTER),
    _p("I_car_z", "kg m^2", 1.97e6, 1.4e6, 2.8e6, "carbody yaw inertia", MANCHESTER),
    _p("h_car", "m", 1.8, 1.5, 2.1, "carbody centre of mass above rail level", MANCHESTER),
    # --- bogie frames ------------------------------------------------------------------------------
    _p("m_bogie", "kg", 2615, 2000, 3500, "bogie frame mass", MANCHESTER),
    _p("I_bogie_x", "kg m^2", 1722, 1200, 2500, "bogie frame roll inertia", MANCHESTER),
    _p("I_bogie_y", "kg m^2", 1476, 1000, 2200, "bogie frame pitch inertia", MANCHESTER),
    _p("I_bogie_z", "kg m^2", 3067, 2200, 4500, "bogie frame yaw inertia", MANCHESTER),
    _p("h_bogie", "m", 0.6, 0.5, 0.7, "bogie frame centre of mass above rail level", MANCHESTER),
    # --- wheelsets ---------------------------------------------------------------------------------
    _p("m_ws", "kg", 1813, 1400, 2200, "wheelset mass", MANCHESTER),
    _p("I_ws_x", "kg m^2", 1120, 800, 1500, "wheelset roll inertia", MANCHESTER),
    _p("I_ws_y", "kg m^2", 112, 80, 150, "wheelset spin (pitch) inertia", MANCHESTER),
    _p("I_ws_z", "kg m^2", 1120, 800, 1500, "wheelset yaw inertia", MANCHESTER),
    _p("r0", "m", 0.46, 0.42, 0.46, "nominal rolling radius (0.92 m wheel, EN 15302 reference)", MANCHESTER),
    # --- geometry ----------------------------------------------------------------------------------
    _p("a_bogie", "m", 9.5, 8.5, 10.5, "half distance between bogie centres", MANCHESTER),
    _p("a_ws", "m", 1.28, 1.1, 1.5, "half wheelbase of a bogie", MANCHESTER),
    _p("b_prim", "m", 1.0, 0.9, 1.1, "half lateral spacing of the primary suspension", MANCHESTER),
    _p("b_sec", "m", 1.0, 0.9, 1.3, "half lateral spacing of the secondary suspension", MANCHESTER),
    _p("l0", "m", 0.75, 0.7, 0.8, "half distance between the wheel-rail contact points",
       "railway-data.md §1 (l0 about 0.75 m)"),
    _p("h_sec", "m", 1.0, 0.8, 1.2, "height of the secondary suspension above rail level", ASSUMED),
    _p("b_yaw", "m", 1.35, 1.2, 1.5, "half lateral spacing of the yaw dampers", ASSUMED),
    _p("h_yaw", "m", 0.65, 0.5, 0.8, "height of the yaw dampers above rail level", ASSUMED),
    # --- primary suspension, per axlebox -----------------------------------------------------------
    _p("k_prim_x", "N/m", 14.68e6, 8e6, 20e6, "primary longitudinal stiffness per axlebox",
       CRH + " (the Manchester coach's 31.4 MN/m makes this car hunt at 320 km/h)"),
    _p("k_prim_y", "N/m", 3.884e6, 2.0e6, 6.0e6, "primary lateral stiffness per axlebox", MANCHESTER),
    _p("k_prim_z", "N/m", 1.22e6, 0.6e6, 1.8e6, "primary vertical stiffness per axlebox", MANCHESTER),
    _p("c_prim_z", "N s/m", 4e3, 1e3, 12e3, "primary vertical damping per axlebox", MANCHESTER),
    # --- secondary suspension, per side (two sides per bogie) --------------------------------------
    _p("k_sec_x", "N/m", 160e3, 80e3, 320e3, "secondary longitudinal stiffness per side", MANCHESTER),
    _p("k_sec_y", "N/m", 160e3, 80e3, 240e3, "secondary lateral stiffness per side", MANCHESTER),
    _p("k_sec_z", "N/m", 430e3, 215e3, 645e3, "secondary vertical stiffness per side", MANCHESTER),
    _p("c_sec_z", "N s/m", 20e3, 8e3, 40e3, "secondary vertical damping per side", MANCHESTER),
    _p("c_sec_y", "N s/m", 16e3, 8e3, 32e3,
       "secondary lateral damping per side (the lateral dampers, one per side, in parallel with the "
       "secondary lateral spring)", TUNED + "; half the Manchester coach's 32 kN s/m, which lets the "
       "car hunt at 320 km/h when the creep coefficients drop by 30 %"),
    _p("c_yaw", "N s/m", 800e3, 400e3, 1.2e6,
       "yaw damper rate per damper (one longitudinal damper per side of each bogie; linear, no series "
       "stiffness, no blow-off)", TUNED + "; railway-data.md §3 cites 300 kN s/m for a yaw damper"),
    _p("k_arb", "N m/rad", 940e3, 400e3, 1.5e6, "anti-roll bar stiffness per bogie (carbody-bogie roll)",
       MANCHESTER),
    # --- wheel-rail contact --------------------------------------------------------------------------
    _p("conicity", "1", 0.25, 0.15, 0.40, "equivalent conicity lambda",
       TUNED + "; railway-data.md §1 gives 0.05-0.3"),
    _p("kalker_scale", "1", 1.0, 0.5, 1.2,
       "factor on the Kalker creep coefficients f11 = f22 (7 MN at 55 kN wheel load, scaled with "
       "load^(2/3), railway-data.md §1)", "1 = Kalker's linear theory (railway-data.md §1)"),
)
"""Every model parameter, in the order of :func:`parameter_table`."""

DEFAULT_IDENTIFIED: tuple[str, ...] = (
    "k_sec_z", "k_prim_z", "c_sec_z", "k_sec_y", "c_sec_y", "c_yaw", "k_prim_y")
"""The default q = 7 identified parameters, in the spirit of the paper (§3.3: the first two both
set the carbody's vertical stiffness, the secondary one closest to the carbody sensors)."""

BY_NAME: dict[str, VehicleParameter] = {p.name: p for p in PARAMETERS}

KALKER_F_REF = 7.0e6
"""Kalker creep coefficient f11 = f22 per wheel, N, at the reference wheel load (railway-data.md §1)."""
KALKER_LOAD_REF = 55.0e3
"""Reference wheel load of :data:`KALKER_F_REF`, N."""


def parameter_table() -> tuple[VehicleParameter, ...]:
    """All model parameters with nominal values, bounds and sources."""
    return PARAMETERS


def nominal_values() -> dict[str, float]:
    """Name -> nominal SI value of every parameter."""
    return {p.name: p.nominal for p in PARAMETERS}


def static_loads(p: dict[str, float]) -> dict[str, float]:
    """Static forces (N) of the symmetric car at rest: per secondary side, per axlebox, per wheel."""
    g = GRAVITY
    sec = p["m_car"] * g / 4.0
    axlebox = (p["m_car"] / 8.0 + p["m_bogie"] / 4.0) * g
    wheel = axlebox + p["m_ws"] * g / 2.0
    return {"secondary_side": sec, "axlebox": axlebox, "wheel": wheel, "axle": 2.0 * wheel}


def creep_coefficient(p: dict[str, float]) -> float:
    """Kalker creep coefficient f11 = f22 per wheel in N.

    f = 7 MN x (N / 55 kN)^(2/3) x kalker_scale with N the static wheel load
    (railway-data.md §1: "an assumption, scale with load^(2/3)").
    """
    n = static_loads(p)["wheel"]
    return KALKER_F_REF * (n / KALKER_LOAD_REF) ** (2.0 / 3.0) * p["kalker_scale"]


def hertz_stiffness(p: dict[str, float]) -> float:
    """Linearised Hertzian vertical contact stiffness per wheel, N/m.

    Hertz: deflection d = G N^(2/3), so k = dN/dd = 1.5 N^(1/3) / G, with the
    wheel-rail constant G = 3.86e-8 r0^-0.115 m/N^(2/3) (r0 in m) as commonly
    cited from Garg & Dukkipati, Dynamics of Railway Vehicle Systems (1984);
    not checked against the book. About 1.35e9 N/m for the default car, which
    puts the wheelset bounce on the rail near 190 Hz, far above the band.
    """
    n = static_loads(p)["wheel"]
    g_const = 3.86e-8 * p["r0"] ** -0.115
    return 1.5 * n ** (1.0 / 3.0) / g_const


def gravitational_stiffness(p: dict[str, float]) -> float:
    """Lateral gravitational stiffness of a wheelset, N/m: W lambda / l0 with W the axle load.

    Coned-wheel approximation (Wickens): a lateral shift y rolls the wheelset
    by lambda y / l0 and tilts the normal forces by that angle.
    """
    return static_loads(p)["axle"] * p["conicity"] / p["l0"]


def check_values(values: dict[str, float]) -> list[str]:
    """Problems with a full parameter dict (unknown names, non-finite or non-positive values)."""
    problems = []
    for name, value in values.items():
        if name not in BY_NAME:
            problems.append(f"unknown parameter '{name}'")
        elif not math.isfinite(value) or value <= 0.0:
            problems.append(f"parameter '{name}' = {value!r} must be a positive finite number "
                            f"({BY_NAME[name].unit})")
    return problems
