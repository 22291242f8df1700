"""Parameter tables of the built-in cars (vehicle presets), each value with its source.

Every physical quantity the model uses is a :class:`VehicleParameter`: name,
SI unit, nominal value, admissible bounds (used when the parameter is
identified), description and **source**. Any of them can be identified by
naming it under ``parameters:`` in a config, or given another nominal value
through the simulator option ``vehicle: {name: value}``; ``vehicle: <preset>``
or ``vehicle: {preset: <preset>, name: value}`` selects a preset.

Presets (:data:`PRESETS`; every preset has the same parameter names, the
articulated one adds those of its articulations, :data:`ARTICULATED_ONLY`;
the model is the same, built on the preset's layout, :mod:`.layout`):

- ``conventional-hs`` (default): a high-speed trailer car on two conventional
  bogies, ICE3/CRH class, 15.5 t axle load. Masses, pitch inertias, geometry,
  vertical primary and secondary suspension of the AVE S103 (ICE3 Velaro E)
  intermediate coach after J. Goicolea, *Simplified mechanical description of
  AVE S-103 (ICE3 Velaro E) high speed train* (UPM, 2014); longitudinal and
  lateral suspension stiffnesses of a CRH380A-class set (public parameter file
  of a CRH-class car, origin not confirmed); lateral damper and Maxwell yaw
  damper (300 kN s/m in series with 10 MN/m) of the high-speed car of Hindawi
  *Mathematical Problems in Engineering* 2019, article 7163732, Table 2;
  values no public source gives are marked as assumptions.
- ``manchester-coach``: the Manchester Benchmark Vehicle 1 (passenger coach;
  Iwnicki, *Vehicle System Dynamics* 30 (1998) 295-313, values as cited by
  public code; the paper itself was not read), with the Maxwell yaw damper of
  the high-speed car above (the benchmark gives none) and the same contact
  and track. A benchmark, not a high-speed car.
- ``tgv-articulated``: a power-car-free section of an articulated TGV-class
  trainset, three carbodies on four bogies (two Jacobs bogies shared by
  adjacent carbodies, an end bogie at each end), eight wheelsets; 17 t axle
  load on every bogie (the section stands for the middle of a rake: each end
  bogie also carries the static load of the neighbouring carbody end outside
  the section, :meth:`.layout.Layout.neighbour_load`). Masses, pitch inertias, geometry and vertical
  suspension of the Eurostar/TMST articulated (TGV-derived) intermediate
  trailer after A. Domenech Monforte, thesis, Universitat Politecnica de
  Valencia 2014 (2-D vehicle model; its values per wheelset and per carbody
  end are halved per axlebox and per side here); the lateral and longitudinal
  suspension as the conventional-hs car (no public TGV value); the
  articulation (a spherical joint as stiff springs, inter-car dampers)
  assumed. The same identified names apply to every suspension of a kind
  (k_sec_z to every carbody end's air springs), as the paper identifies one
  value per kind.

Wheel-rail contact: the linear creep coefficients are Kalker's
(:func:`creep_coefficients`): f11 = G a b C11, f22 = G a b C22 with the
Hertzian contact ellipse (a, b) of the wheel load, the wheel rolling radius
and the rail crown radius, and Kalker's coefficient tables; ``kalker_scale``
multiplies both (1 = Kalker's linear theory).

Conventions: x forward, y to the left, z up (right-handed); "per axlebox",
"per side", "per damper", "per wheel" say how many elements share a value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

GRAVITY = 9.81
"""Gravitational acceleration, m/s^2."""

YOUNG = 210e9
"""Young's modulus of wheel and rail steel, Pa."""
POISSON = 0.28
"""Poisson's ratio of wheel and rail steel."""

# --- sources ------------------------------------------------------------------------------------------
ICE3 = ("AVE S103 / ICE3 Velaro E intermediate coach: Goicolea, Simplified mechanical description of "
        "AVE S-103 (ICE3 Velaro E) high speed train, UPM 2014")
CRH = "CRH380A-class high-speed car (public parameter file; origin not confirmed)"
HMPE = ("high-speed car with Maxwell yaw dampers: Mathematical Problems in Engineering 2019, "
        "article 7163732, Table 2")
MANCHESTER = "Manchester Benchmark Vehicle 1 (Iwnicki, Vehicle System Dynamics 30 (1998) 295-313)"
TMST = ("Eurostar/TMST articulated (TGV-derived) intermediate trailer: Domenech Monforte, Influencia del modelo de "
        "vehiculo en la prediccion del comportamiento a flexion de puentes isostaticos de ferrocarril para trafico "
        "de alta velocidad, thesis, Universitat Politecnica de Valencia 2014, doi:10.4995/Thesis/10251/36740 "
        "(2-D vehicle model: values per wheelset and per carbody end)")
ASSUMED = "assumption (typical value; not in the cited sources)"
EN13674 = "60E1 rail head crown radius 300 mm (EN 13674-1)"
KLINGEL = "half distance between the contact points of a standard-gauge wheelset (1.5 m apart)"
TRACK = ("lumped ballasted-track support per wheel, chosen so that the P2 resonance (wheelset on the track "
         "support) is about 65 Hz with damping ratio about 0.35: the 50-80 Hz, well-damped range of "
         "Jenkins et al., The effect of track and vehicle parameters on wheel/rail vertical dynamic forces, "
         "Railway Engineering Journal 3 (1974) 2-16 (assumption for the split mass / stiffness / damping)")


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


CONVENTIONAL_HS: tuple[VehicleParameter, ...] = (
    # --- carbody -----------------------------------------------------------------------------------
    _p("m_car", "kg", 47800, 36000, 56000, "carbody mass", ICE3),
    _p("I_car_x", "kg m^2", 85e3, 60e3, 130e3, "carbody roll inertia about its centre of mass",
       ASSUMED + ": the Manchester coach's 56.8e3 kg m^2 scaled by the mass ratio"),
    _p("I_car_y", "kg m^2", 1.958e6, 1.4e6, 2.8e6, "carbody pitch inertia", ICE3),
    _p("I_car_z", "kg m^2", 1.958e6, 1.4e6, 2.8e6, "carbody yaw inertia",
       ASSUMED + ": equal to the pitch inertia, as for the Manchester coach"),
    _p("h_car", "m", 1.8, 1.5, 2.1, "carbody centre of mass above rail level", MANCHESTER),
    # --- bogie frames ------------------------------------------------------------------------------
    _p("m_bogie", "kg", 3500, 2400, 4200, "bogie frame mass", ICE3),
    _p("I_bogie_x", "kg m^2", 2300, 1600, 3200, "bogie frame roll inertia",
       ASSUMED + ": the Manchester bogie's 1722 kg m^2 scaled by the mass ratio"),
    _p("I_bogie_y", "kg m^2", 1715, 1200, 2500, "bogie frame pitch inertia", ICE3),
    _p("I_bogie_z", "kg m^2", 4100, 2800, 5600, "bogie frame yaw inertia",
       ASSUMED + ": the Manchester bogie's 3067 kg m^2 scaled by the mass ratio"),
    _p("h_bogie", "m", 0.6, 0.5, 0.7, "bogie frame centre of mass above rail level", MANCHESTER),
    # --- wheelsets ---------------------------------------------------------------------------------
    _p("m_ws", "kg", 1800, 1400, 2200, "wheelset mass", ICE3),
    _p("I_ws_x", "kg m^2", 1120, 800, 1500, "wheelset roll inertia", MANCHESTER),
    _p("I_ws_y", "kg m^2", 112, 80, 150, "wheelset spin (pitch) inertia", MANCHESTER),
    _p("I_ws_z", "kg m^2", 1120, 800, 1500, "wheelset yaw inertia", MANCHESTER),
    _p("r0", "m", 0.46, 0.42, 0.46, "nominal rolling radius (920 mm wheel, EN 15302 reference wheel)",
       "EN 15302 reference wheel diameter 920 mm (ICE3 and TGV wheels are 920 mm new)"),
    # --- geometry ----------------------------------------------------------------------------------
    _p("a_bogie", "m", 8.6875, 8.0, 9.5, "half distance between bogie centres", ICE3),
    _p("a_ws", "m", 1.25, 1.1, 1.5, "half wheelbase of a bogie", ICE3),
    _p("b_prim", "m", 1.0, 0.9, 1.1, "half lateral spacing of the primary suspension", MANCHESTER),
    _p("b_sec", "m", 1.0, 0.9, 1.3, "half lateral spacing of the secondary suspension", MANCHESTER),
    _p("l0", "m", 0.75, 0.7, 0.8, "half distance between the wheel-rail contact points", KLINGEL),
    _p("h_sec", "m", 1.0, 0.8, 1.2, "height of the secondary suspension above rail level", ASSUMED),
    _p("b_yaw", "m", 1.35, 1.2, 1.5, "half lateral spacing of the yaw dampers", HMPE),
    _p("h_yaw", "m", 0.65, 0.5, 0.8, "height of the yaw dampers above rail level", ASSUMED),
    _p("h_trac", "m", 0.65, 0.5, 0.8, "height of the traction rod above rail level",
       ASSUMED + ": at the yaw dampers' height, as in bogies with a low traction link"),
    # --- primary suspension, per axlebox -----------------------------------------------------------
    _p("k_prim_x", "N/m", 14.68e6, 8e6, 20e6, "primary longitudinal stiffness per axlebox", CRH),
    _p("c_prim_x", "N s/m", 20e3, 5e3, 50e3,
       "primary longitudinal damping per axlebox (hysteresis of the rubber guide bushes, as a dashpot)",
       ASSUMED + ": loss factor about 0.2 of the bushes at the 25 Hz bogie longitudinal mode"),
    _p("k_prim_y", "N/m", 6.47e6, 3.0e6, 9.0e6, "primary lateral stiffness per axlebox", CRH),
    _p("k_prim_z", "N/m", 1.2e6, 0.8e6, 1.6e6, "primary vertical stiffness per axlebox", ICE3),
    _p("c_prim_z", "N s/m", 10e3, 4e3, 20e3, "primary vertical damping per axlebox", ICE3),
    # --- secondary suspension, per side (two sides per bogie) --------------------------------------
    _p("k_sec_x", "N/m", 160e3, 80e3, 320e3, "secondary longitudinal stiffness per side", CRH),
    _p("k_sec_y", "N/m", 160e3, 100e3, 240e3, "secondary lateral stiffness per side", CRH),
    _p("k_sec_z", "N/m", 350e3, 230e3, 500e3, "secondary vertical stiffness per side", ICE3),
    _p("c_sec_z", "N s/m", 20e3, 10e3, 35e3,
       "secondary vertical damping per side (the damper of a Maxwell element with the series stiffness "
       "k_sec_z_s)", ICE3),
    _p("k_sec_z_s", "N/m", 5e6, 2e6, 10e6,
       "series stiffness of each secondary vertical damper (its rubber end mounts)",
       ASSUMED + ": rubber end mounts of hydraulic dampers, a few MN/m; modelled in series with the damper as "
       "recommended by Bruni et al., Modelling of suspension components in a rail vehicle dynamics context, "
       "Vehicle System Dynamics 49(7), 2011"),
    _p("c_sec_y", "N s/m", 30e3, 15e3, 60e3,
       "secondary lateral damping per side (one lateral damper per side, in parallel with the secondary "
       "lateral spring)", HMPE),
    _p("c_yaw", "N s/m", 300e3, 150e3, 450e3,
       "yaw damper rate per damper (one longitudinal damper per side of each bogie; the damper of a Maxwell "
       "element with the series stiffness k_yaw_s)", HMPE),
    _p("k_yaw_s", "N/m", 10e6, 5e6, 20e6,
       "series stiffness of each yaw damper (rubber bushes and oil column of the Maxwell element)", HMPE),
    _p("k_trac", "N/m", 5e6, 2e6, 10e6,
       "longitudinal stiffness of the traction rod between bogie frame and carbody, per bogie", ASSUMED),
    _p("k_arb", "N m/rad", 2.0e6, 1.0e6, 3.0e6, "anti-roll bar stiffness per bogie (carbody-bogie roll)",
       ASSUMED),
    # --- wheel-rail contact --------------------------------------------------------------------------
    _p("conicity", "1", 0.15, 0.05, 0.40, "equivalent conicity lambda",
       "new high-speed wheel/rail profile pairs: about 0.05-0.15 (in-service limit above 230 km/h: 0.25 "
       "mean over 100 m, EN 14363 / UIC 518)"),
    _p("kalker_scale", "1", 1.0, 0.5, 1.2,
       "factor on Kalker's linear creep coefficients f11, f22 (computed from the wheel load and the "
       "Hertzian contact ellipse)", "1 = Kalker's linear theory (Kalker, Three-dimensional elastic "
       "bodies in rolling contact, 1990)"),
    _p("r_rail", "m", 0.30, 0.2, 0.5, "transverse (crown) radius of the rail head at the contact point",
       EN13674),
    # --- track support, per wheel ------------------------------------------------------------------
    _p("m_track", "kg", 200.0, 100.0, 400.0, "equivalent rail and sleeper mass under each wheel", TRACK),
    _p("k_track", "N/m", 180e6, 80e6, 300e6, "vertical stiffness of rail pad and ballast under each wheel",
       TRACK),
    _p("c_track", "N s/m", 300e3, 100e3, 600e3, "vertical damping of rail pad and ballast under each wheel",
       TRACK),
)
"""The ``conventional-hs`` preset (default)."""


def _override(base: tuple[VehicleParameter, ...], changes: dict[str, tuple]) -> tuple[VehicleParameter, ...]:
    """``base`` with ``changes``: name -> (nominal, lower, upper, source)."""
    out = []
    for p in base:
        if p.name in changes:
            nominal, lower, upper, source = changes[p.name]
            p = replace(p, nominal=float(nominal), lower=float(lower), upper=float(upper), source=source)
        out.append(p)
    return tuple(out)


MANCHESTER_COACH: tuple[VehicleParameter, ...] = _override(CONVENTIONAL_HS, {
    "m_car": (32000, 24000, 48000, MANCHESTER),
    "I_car_x": (56.8e3, 40e3, 90e3, MANCHESTER),
    "I_car_y": (1.97e6, 1.4e6, 2.8e6, MANCHESTER),
    "I_car_z": (1.97e6, 1.4e6, 2.8e6, MANCHESTER),
    "m_bogie": (2615, 2000, 3500, MANCHESTER),
    "I_bogie_x": (1722, 1200, 2500, MANCHESTER),
    "I_bogie_y": (1476, 1000, 2200, MANCHESTER),
    "I_bogie_z": (3067, 2200, 4500, MANCHESTER),
    "m_ws": (1813, 1400, 2200, MANCHESTER),
    "a_bogie": (9.5, 8.5, 10.5, MANCHESTER),
    "a_ws": (1.28, 1.1, 1.5, MANCHESTER),
    "k_prim_x": (31.391e6, 15e6, 40e6, MANCHESTER),
    "k_prim_y": (3.884e6, 2.0e6, 6.0e6, MANCHESTER),
    "k_prim_z": (1.22e6, 0.6e6, 1.8e6, MANCHESTER),
    "c_prim_z": (4e3, 1e3, 12e3, MANCHESTER),
    "k_sec_x": (160e3, 80e3, 320e3, MANCHESTER),
    "k_sec_y": (160e3, 80e3, 240e3, MANCHESTER),
    "k_sec_z": (430e3, 215e3, 645e3, MANCHESTER),
    "c_sec_z": (20e3, 8e3, 40e3, MANCHESTER),
    "c_sec_y": (32e3, 16e3, 48e3, MANCHESTER),
    "c_yaw": (300e3, 150e3, 450e3, HMPE + " (the benchmark coach has no yaw damper data)"),
    "k_arb": (940e3, 400e3, 1.5e6, MANCHESTER),
    "conicity": (0.15, 0.05, 0.40, "equivalent conicity used with the benchmark (0.05-0.3 in the literature)"),
})
"""The ``manchester-coach`` preset (benchmark)."""

AS_CONVENTIONAL = "no public TGV value: as the conventional-hs car"
ARTICULATED_ONLY = ("k_art", "c_art", "h_art", "c_ic", "b_ic", "h_ic")
"""Parameters of the articulation between adjacent carbodies (articulated presets only)."""

TGV_ARTICULATED: tuple[VehicleParameter, ...] = _override(CONVENTIONAL_HS, {
    "m_car": (27300, 20000, 34000, TMST + "; the empty body's 22,525 kg there plus payload, derived for the 17 t "
              "axle load of TGV sets on the Jacobs bogies (2 x 17 t = m_car + m_bogie + 2 m_ws)"),
    "I_car_x": (48.5e3, 35e3, 70e3, ASSUMED + ": the conventional-hs value scaled by the mass ratio"),
    "I_car_y": (0.98e6, 0.7e6, 1.3e6, TMST + "; the body's 810,000 kg m^2 there scaled by the mass ratio "
                "27.3 / 22.5 t (payload spread along the body)"),
    "I_car_z": (0.98e6, 0.7e6, 1.3e6, ASSUMED + ": equal to the pitch inertia"),
    "h_car": (1.8, 1.5, 2.1, ASSUMED + ": as the conventional-hs car"),
    "m_bogie": (2900, 2400, 3500, TMST),
    "I_bogie_x": (1900, 1300, 2700, ASSUMED + ": the Manchester bogie's 1722 kg m^2 scaled by the mass ratio"),
    "I_bogie_y": (2508, 1800, 3300, TMST),
    "I_bogie_z": (4400, 3100, 6000, ASSUMED + ": I_bogie_x + I_bogie_y (flat frame, perpendicular-axis "
                  "theorem)"),
    "m_ws": (1900, 1500, 2300, TMST),
    "a_bogie": (9.35, 8.5, 10.0, TMST + ": bogie pivots 18.7 m apart"),
    "a_ws": (1.5, 1.3, 1.6, TMST + ": 3 m bogie wheelbase (TGV bogies)"),
    "k_prim_z": (1.0e6, 0.65e6, 1.35e6, TMST + ": 2.0 MN/m per wheelset, halved per axlebox"),
    "c_prim_z": (6e3, 3e3, 12e3, TMST + ": 12 kN s/m per wheelset, halved per axlebox"),
    "k_sec_z": (290e3, 190e3, 420e3, TMST + ": 580 kN/m per carbody end, halved per side"),
    "c_sec_z": (10e3, 5e3, 20e3, TMST + ": 20 kN s/m per carbody end for the end trailer EC1, halved per side "
                "(the intermediate-trailer file gives none)"),
    "k_prim_x": (14.68e6, 8e6, 20e6, AS_CONVENTIONAL + " (" + CRH + ")"),
    "k_prim_y": (6.47e6, 3.0e6, 9.0e6, AS_CONVENTIONAL + " (" + CRH + ")"),
    "k_sec_x": (160e3, 80e3, 320e3, AS_CONVENTIONAL + " (" + CRH + ")"),
    "k_sec_y": (160e3, 100e3, 240e3, AS_CONVENTIONAL + " (" + CRH + ")"),
    "c_sec_y": (30e3, 15e3, 60e3, AS_CONVENTIONAL + " (" + HMPE + ")"),
    "c_yaw": (300e3, 150e3, 450e3, AS_CONVENTIONAL + " (" + HMPE + ")"),
    "k_yaw_s": (10e6, 5e6, 20e6, AS_CONVENTIONAL + " (" + HMPE + ")"),
    "k_arb": (1.0e6, 0.5e6, 2.0e6, ASSUMED + ": the conventional-hs value scaled by the carbody mass per end"),
}) + (
    # --- articulation between adjacent carbodies, above each Jacobs bogie -------------------------------
    _p("k_art", "N/m", 1e9, 3e8, 3e9, "stiffness of the articulation (a spherical joint between adjacent "
       "carbody ends, as three springs x, y, z)", ASSUMED + ": stiff, so that the relative translation modes of "
       "the carbody ends lie above 50 Hz"),
    _p("c_art", "N s/m", 1e6, 3e5, 3e6, "damping of the articulation springs (x, y, z)",
       ASSUMED + ": damping ratio about 0.2 of the articulation modes"),
    _p("h_art", "m", 1.2, 1.0, 1.5, "height of the articulation above rail level", ASSUMED),
    _p("c_ic", "N s/m", 50e3, 20e3, 100e3, "inter-car damper rate, per damper (two longitudinal dampers per "
       "articulation, at roof level, against relative yaw and pitch of adjacent carbodies)", ASSUMED),
    _p("b_ic", "m", 1.0, 0.8, 1.2, "half lateral spacing of the inter-car dampers", ASSUMED),
    _p("h_ic", "m", 3.3, 3.0, 3.6, "height of the inter-car dampers above rail level", ASSUMED + ": roof level"),
)
"""The ``tgv-articulated`` preset: a section of an articulated TGV-class trainset."""

PRESETS: dict[str, tuple[VehicleParameter, ...]] = {
    "conventional-hs": CONVENTIONAL_HS,
    "manchester-coach": MANCHESTER_COACH,
    "tgv-articulated": TGV_ARTICULATED,
}
"""Preset name -> parameter table (the names of conventional-hs in every preset, in the same order; articulated
presets add :data:`ARTICULATED_ONLY`)."""

LAYOUTS: dict[str, int] = {"tgv-articulated": 3}
"""Articulated presets -> number of carbodies (the others are one car on two bogies, :mod:`.layout`)."""

DEFAULT_PRESET = "conventional-hs"

PARAMETERS: tuple[VehicleParameter, ...] = PRESETS[DEFAULT_PRESET]
"""Every model parameter of the default preset, in the order of :func:`parameter_table`."""

DEFAULT_IDENTIFIED: tuple[str, ...] = (
    "k_sec_z", "k_prim_z", "c_sec_z", "k_sec_y", "c_sec_y", "c_yaw", "k_prim_y")
"""The default q = 7 identified parameters, in the spirit of the paper (§3.3: the first two both
set the carbody's vertical stiffness, the secondary one closest to the carbody sensors)."""

CALIBRATABLE: tuple[str, ...] = ("k_sec_z_s", "k_yaw_s", "kalker_scale", "conicity")
"""Model parameters that are uncertain but not identified (their values are assumptions or ranges in the
tables above): the series stiffnesses of the secondary vertical and yaw dampers' mounts, the factor on
Kalker's creep coefficients, the equivalent conicity. A reference date calibrates them
(``identifiability.model_error.method: linearised``)."""

BY_NAME: dict[str, VehicleParameter] = {p.name: p for p in PARAMETERS}

ELEMENT_KINDS: dict[str, tuple[str, ...]] = {
    "primary": ("k_prim_x", "c_prim_x", "k_prim_y", "k_prim_z", "c_prim_z"),
    "secondary": ("k_sec_x", "k_sec_y", "k_sec_z", "c_sec_z", "k_sec_z_s", "c_sec_y"),
    "yaw": ("c_yaw", "k_yaw_s"),
    "bogie": ("k_trac", "k_arb"),
}
"""Where each suspension kind sits, element by element (:meth:`.layout.Layout.element_tags`): per axlebox
(primary), per carbody end and side (secondary: air spring, vertical and lateral dampers), per bogie and side
(yaw dampers), per bogie (traction rod, anti-roll bar). A group ``kind[tag,...]`` in a parameter dict sets
the elements of ``kind`` carrying those tags (:func:`element_view`)."""


@lru_cache(maxsize=4096)
def _group_key(key: str) -> tuple[str, frozenset] | None:
    if not key.endswith("]") or "[" not in key:
        return None
    kind, rest = key[:-1].split("[", 1)
    return kind.strip(), frozenset(t.strip() for t in rest.split(","))


def element_view(q: dict[str, float], kinds: tuple[str, ...], tags: tuple[str, ...]) -> dict[str, float]:
    """The values one element sees: ``q`` with each of ``kinds`` replaced by the value of the most specific
    group in ``q`` (``kind[tag,...]``, its tags among the element's ``tags``) that covers the element; ``q``
    itself (the same object) when no group covers it, so that kind-level values give identical results."""
    best: dict[str, tuple[int, float]] = {}
    for key, value in q.items():
        parsed = _group_key(key) if "[" in key else None
        if parsed is None:
            continue
        kind, ktags = parsed
        if kind in kinds and ktags <= set(tags) and len(ktags) >= best.get(kind, (-1, 0.0))[0]:
            best[kind] = (len(ktags), value)
    if not best:
        return q
    return {**q, **{k: v for k, (_, v) in best.items()}}


def by_name(preset: str = DEFAULT_PRESET) -> dict[str, VehicleParameter]:
    """Name -> parameter of a preset."""
    return {p.name: p for p in PRESETS[preset]}


def parameter_table(preset: str = DEFAULT_PRESET) -> tuple[VehicleParameter, ...]:
    """All model parameters of a preset with nominal values, bounds and sources.

    :raises KeyError: unknown preset.
    """
    return PRESETS[preset]


def nominal_values(preset: str = DEFAULT_PRESET) -> dict[str, float]:
    """Name -> nominal SI value of every parameter of a preset."""
    return {p.name: p.nominal for p in PRESETS[preset]}


def static_loads(p: dict[str, float]) -> dict[str, float]:
    """Static forces (N) of the symmetric car at rest: per secondary side (per carbody end), per axlebox,
    per wheel, per axle, for a bogie that carries one carbody end (a Jacobs bogie of an articulated
    layout carries two: :meth:`.layout.Layout.wheel_load`)."""
    g = GRAVITY
    sec = p["m_car"] * g / 4.0
    axlebox = (p["m_car"] / 8.0 + p["m_bogie"] / 4.0) * g
    wheel = axlebox + p["m_ws"] * g / 2.0
    return {"secondary_side": sec, "axlebox": axlebox, "wheel": wheel, "axle": 2.0 * wheel}


# --- Kalker's creep coefficients -------------------------------------------------------------------------
# Kalker's linear-theory coefficients C11 (longitudinal) and C22 (lateral) for an elliptical contact with
# semi-axis a in the rolling direction and b across it, for Poisson's ratio 0.25 and 0.5 (J.J. Kalker,
# On the rolling contact of two elastic bodies in the presence of dry friction, thesis, Delft 1967; the
# table as reproduced in Kalker, Three-dimensional elastic bodies in rolling contact, Kluwer 1990, and in
# Garg & Dukkipati, Dynamics of railway vehicle systems, 1984). Rows: g, C11(0.25), C11(0.5), C22(0.25),
# C22(0.5). First block g = a/b <= 1, second block g = b/a <= 1.
_KALKER_A_OVER_B = np.array([
    (0.1, 3.31, 4.85, 2.52, 2.53), (0.2, 3.37, 4.81, 2.63, 2.66), (0.3, 3.44, 4.80, 2.75, 2.81),
    (0.4, 3.53, 4.82, 2.88, 2.98), (0.5, 3.62, 4.83, 3.01, 3.14), (0.6, 3.72, 4.91, 3.14, 3.31),
    (0.7, 3.81, 4.97, 3.28, 3.48), (0.8, 3.91, 5.05, 3.41, 3.65), (0.9, 4.01, 5.12, 3.54, 3.82),
    (1.0, 4.12, 5.20, 3.67, 3.98)])
_KALKER_B_OVER_A = np.array([
    (0.1, 11.7, 12.9, 12.8, 16.0), (0.2, 7.78, 8.82, 8.14, 9.79), (0.3, 6.34, 7.34, 6.40, 7.51),
    (0.4, 5.57, 6.57, 5.48, 6.31), (0.5, 5.10, 6.11, 4.90, 5.56), (0.6, 4.78, 5.80, 4.50, 5.04),
    (0.7, 4.54, 5.58, 4.21, 4.67), (0.8, 4.36, 5.42, 3.99, 4.39), (0.9, 4.22, 5.30, 3.81, 4.16),
    (1.0, 4.12, 5.20, 3.67, 3.98)])


def kalker_c11_c22(a_over_b: float, nu: float = POISSON) -> tuple[float, float]:
    """Kalker's C11, C22 for the semi-axis ratio a/b (a: rolling direction), linear in nu between 0.25
    and 0.5 and in the axis ratio between the table rows (clamped to 0.1-10)."""
    w = (nu - 0.25) / 0.25
    if a_over_b <= 1.0:
        tab, g = _KALKER_A_OVER_B, max(a_over_b, 0.1)
    else:
        tab, g = _KALKER_B_OVER_A, max(1.0 / a_over_b, 0.1)
    c11 = np.interp(g, tab[:, 0], tab[:, 1] + w * (tab[:, 2] - tab[:, 1]))
    c22 = np.interp(g, tab[:, 0], tab[:, 3] + w * (tab[:, 4] - tab[:, 3]))
    return float(c11), float(c22)


def hertz_ellipse(load: float, curvature_x: float, curvature_y: float, young: float = YOUNG,
                  nu: float = POISSON) -> tuple[float, float]:
    """Semi-axes (a, b) in m of the Hertzian contact ellipse: a along x (rolling), b along y.

    :param load: normal force, N.
    :param curvature_x, curvature_y: relative curvature half-sums A = (1/R_wheel,x + 1/R_rail,x) / 2 and
        B = (1/R_wheel,y + 1/R_rail,y) / 2, 1/m (A: the wheel's rolling radius; B: the rail crown, a
        conical wheel tread).
    Hertz's solution (Johnson, Contact mechanics, 1985, §4.2): with e^2 = 1 - (b/a)^2 for a >= b,
    B/A = (E(e)/(1 - e^2) - K(e)) / (K(e) - E(e)) and a^3 = 3 P (K - E) / (2 pi A E* e^2),
    E* = E / (2 (1 - nu^2)) (identical materials); K, E complete elliptic integrals of parameter e^2.
    """
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipk

    e_star = young / (2.0 * (1.0 - nu ** 2))
    small, large = min(curvature_x, curvature_y), max(curvature_x, curvature_y)
    ratio = large / small
    if ratio < 1.0 + 1e-9:   # circular contact of radius (3 P R / 4 E*)^(1/3), R = 1 / (2 A)
        r = (3.0 * load / (4.0 * e_star * 2.0 * small)) ** (1.0 / 3.0)
        return r, r
    m = brentq(lambda m: (ellipe(m) / (1.0 - m) - ellipk(m)) / (ellipk(m) - ellipe(m)) - ratio, 1e-12, 1 - 1e-12)
    k, e = ellipk(m), ellipe(m)
    longer = (3.0 * load * (k - e) / (2.0 * math.pi * small * e_star * m)) ** (1.0 / 3.0)
    shorter = longer * math.sqrt(1.0 - m)
    return (longer, shorter) if curvature_x <= curvature_y else (shorter, longer)


def creep_coefficients(p: dict[str, float], wheel: float | None = None) -> tuple[float, float]:
    """Kalker's linear creep coefficients (f11, f22) per wheel in N, times ``kalker_scale``.

    f11 = G a b C11, f22 = G a b C22 with G = E / (2 (1 + nu)) the shear
    modulus, (a, b) the Hertzian ellipse of the static wheel load
    (:func:`hertz_ellipse`, wheel rolling radius r0, rail crown radius
    r_rail, conical tread) and Kalker's C11, C22 (:func:`kalker_c11_c22`).
    About 12.2 and 11.0 MN for the conventional-hs car (wheel load 76 kN);
    9.7 and 8.8 MN at 54.5 kN (the Manchester coach), inside the 9.4-10.4 and
    8.3-9.2 MN published for that load and a 300 mm rail crown. Spin creep
    (f23, f33) is left out. ``wheel``: the static wheel load, N (default: that
    of :func:`static_loads`).
    """
    n = static_loads(p)["wheel"] if wheel is None else wheel
    a, b = hertz_ellipse(n, 0.5 / p["r0"], 0.5 / p["r_rail"])
    c11, c22 = kalker_c11_c22(a / b)
    shear = YOUNG / (2.0 * (1.0 + POISSON))
    s = p["kalker_scale"]
    return s * shear * a * b * c11, s * shear * a * b * c22


def hertz_stiffness(p: dict[str, float], wheel: float | None = None) -> float:
    """Linearised Hertzian vertical contact stiffness per wheel, N/m.

    Hertz: deflection d = G N^(2/3), so k = dN/dd = 1.5 N^(1/3) / G, with the
    wheel-rail constant G = 3.86e-8 r0^-0.115 m/N^(2/3) (r0 in m) as commonly
    cited from Garg & Dukkipati, Dynamics of Railway Vehicle Systems (1984).
    About 1.5e9 N/m for the default car: the wheel on the rail mass
    (m_track) then vibrates near 490 Hz, damped by the track support
    (damping ratio 0.2). ``wheel``: the static wheel load, N (default: that of :func:`static_loads`).
    """
    n = static_loads(p)["wheel"] if wheel is None else wheel
    g_const = 3.86e-8 * p["r0"] ** -0.115
    return 1.5 * n ** (1.0 / 3.0) / g_const


def gravitational_stiffness(p: dict[str, float], wheel: float | None = None) -> float:
    """Lateral gravitational stiffness of a wheelset, N/m: W lambda / l0 with W the axle load.

    Coned-wheel approximation (Wickens): a lateral shift y rolls the wheelset
    by lambda y / l0 and tilts the normal forces by that angle. ``wheel``: the
    static wheel load, N (default: that of :func:`static_loads`; W = 2 wheel).
    """
    axle = static_loads(p)["axle"] if wheel is None else 2.0 * wheel
    return axle * p["conicity"] / p["l0"]


def check_values(values: dict[str, float], known: dict | None = None) -> list[str]:
    """Problems with a parameter dict (unknown names, non-finite or non-positive values)."""
    known = BY_NAME if known is None else known
    problems = []
    for name, value in values.items():
        if name not in known and (_group_key(name) is None or _group_key(name)[0] not in known):
            problems.append(f"unknown parameter '{name}'")
        elif not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0.0:
            problems.append(f"parameter '{name}' = {value!r} must be a positive finite number "
                            f"({known[name.split('[')[0]].unit})")
    return problems
