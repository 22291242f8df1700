"""Which bodies a vehicle has and how they are attached: one car on two bogies, or an articulated rake.

A :class:`Layout` names the bodies and places them; the model
(:mod:`.model`) builds the same suspension elements for every layout:

- ``Layout(1)``: one carbody (``carbody``) on two bogies (``bogie_front``,
  ``bogie_rear``), wheelsets 1-4 (1 leads): a conventional car.
- ``Layout(n, articulated=True)``: n carbodies (``carbody_1`` .. ``carbody_n``,
  1 leads) on n + 1 bogies (``bogie_1`` .. ``bogie_<n+1>``), wheelsets
  1 .. 2 (n + 1): a section of an articulated trainset. Bogies 2 .. n are
  Jacobs bogies shared by two carbodies; bogies 1 and n + 1 carry one carbody
  end each. Adjacent carbodies meet at an articulation above the Jacobs
  bogie's centre.
- ``Layout(n, articulated=True, outer_neighbours=True)``: the same section
  cut from the middle of a rake: its end bogies are Jacobs bogies too, each
  also carrying the end of a neighbouring carbody outside the section. That
  carbody is not modelled; the static load of its end (half a carbody, the
  section's carbody mass) acts on the end bogie as a dead load at its
  secondary suspension seats (:meth:`Layout.neighbour_load`), so that every
  bogie carries two carbody ends (the same wheel loads, Hertz stiffness,
  Kalker coefficients and gravitational stiffness on every wheelset).

Every carbody end rests on its own secondary suspension (per side: springs
x, y, z, vertical and lateral dampers): a Jacobs bogie carries two carbody
ends, hence twice the secondary suspension of an end bogie, and every
carbody sees the same suspension at both ends. The traction rod, the yaw
dampers and the anti-roll bar of a bogie connect it to its *carrying*
carbody: the first carbody it carries (the one ahead, for a Jacobs bogie).

Positions: x forward from the middle of the layout; bogie pivots 2 a_bogie
apart; the carbody between pivots b and b + 1 is centred between them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import parameters as P


@dataclass(frozen=True)
class Layout:
    """The bodies of a vehicle: ``n_cars`` carbodies, conventional (one car) or articulated."""

    n_cars: int = 1
    articulated: bool = False
    outer_neighbours: bool = False

    # ------------------------------------------------------------------ names
    @property
    def carbodies(self) -> tuple[str, ...]:
        if not self.articulated:
            return ("carbody",)
        return tuple(f"carbody_{c + 1}" for c in range(self.n_cars))

    @property
    def bogies(self) -> tuple[str, ...]:
        if not self.articulated:
            return ("bogie_front", "bogie_rear")
        return tuple(f"bogie_{b + 1}" for b in range(self.n_cars + 1))

    @property
    def n_wheelsets(self) -> int:
        return 2 * len(self.bogies)

    @property
    def wheelsets(self) -> tuple[str, ...]:
        return tuple(f"wheelset_{j + 1}" for j in range(self.n_wheelsets))

    @property
    def bodies(self) -> tuple[str, ...]:
        """Every rigid body: carbodies, bogies, wheelsets (the order of the model's nodes)."""
        return self.carbodies + self.bogies + self.wheelsets

    # ------------------------------------------------------------------ attachments
    def bogie_cars(self, b: int) -> tuple[tuple[int, float], ...]:
        """The carbody ends bogie ``b`` carries: ``(carbody index, pivot x relative to that carbody's centre
        in units of a_bogie, +1 front end or -1 rear end)``; the first is the carrying carbody."""
        if not self.articulated:
            return ((0, 1.0 if b == 0 else -1.0),)
        ends = []
        if b > 0:
            ends.append((b - 1, -1.0))     # rear end of the carbody ahead
        if b < self.n_cars:
            ends.append((b, 1.0))          # front end of the carbody behind
        return tuple(ends)

    def neighbour_ends(self, b: int) -> int:
        """Number of carbody ends outside the section that bogie ``b`` also carries (0 or 1): one on each
        end bogie of an articulated section with ``outer_neighbours``."""
        end_bogie = self.articulated and b in (0, self.n_cars)
        return int(self.outer_neighbours and end_bogie)

    def articulations(self) -> tuple[tuple[int, int], ...]:
        """Pairs (carbody ahead, carbody behind) joined by an articulation above a Jacobs bogie."""
        if not self.articulated:
            return ()
        return tuple((c, c + 1) for c in range(self.n_cars - 1))

    # ------------------------------------------------------------------ positions, m
    def carbody_x(self, values: dict[str, float]) -> np.ndarray:
        if not self.articulated:
            return np.zeros(1)
        a = values["a_bogie"]
        return np.array([(self.n_cars - 1 - 2 * c) * a for c in range(self.n_cars)])

    def bogie_x(self, values: dict[str, float]) -> np.ndarray:
        a = values["a_bogie"]
        if not self.articulated:
            return np.array([a, -a])
        return np.array([(self.n_cars - 2 * b) * a for b in range(self.n_cars + 1)])

    def wheelset_x(self, values: dict[str, float]) -> np.ndarray:
        """``(n_wheelsets,)`` longitudinal positions relative to the middle of the layout, forward positive."""
        a, w = values["a_bogie"], values["a_ws"]
        if not self.articulated:
            return np.array([a + w, a - w, -a + w, -a - w])
        return np.array([x + s * w for x in self.bogie_x(values) for s in (1.0, -1.0)])

    # ------------------------------------------------------------------ static loads, N
    def carried_ends(self, b: int) -> int:
        """Number of carbody ends whose weight bogie ``b`` carries (those of the section and its neighbours)."""
        return len(self.bogie_cars(b)) + self.neighbour_ends(b)

    def neighbour_load(self, values: dict[str, float], b: int) -> float:
        """Static force (N, downward) of the neighbouring carbody end outside the section on bogie ``b``: half
        a carbody of the section's mass on an end bogie with ``outer_neighbours``, else 0."""
        return self.neighbour_ends(b) * values["m_car"] / 2.0 * P.GRAVITY

    def axlebox_load(self, values: dict[str, float], b: int) -> float:
        """Static force per axlebox of bogie ``b``: its carbody ends (half a carbody each) and its frame."""
        n_ends = self.carried_ends(b)
        if n_ends == 1:
            return P.static_loads(values)["axlebox"]
        return (values["m_car"] / 8.0 * n_ends + values["m_bogie"] / 4.0) * P.GRAVITY

    def wheel_load(self, values: dict[str, float], j: int) -> float:
        """Static force per wheel of wheelset ``j`` (0-based)."""
        b = j // 2
        if self.carried_ends(b) == 1:
            return P.static_loads(values)["wheel"]
        return self.axlebox_load(values, b) + values["m_ws"] * P.GRAVITY / 2.0

    def mean_wheel_load(self, values: dict[str, float]) -> float:
        return float(np.mean([self.wheel_load(values, j) for j in range(self.n_wheelsets)]))


    # ------------------------------------------------------------------ elements
    def element_tags(self, placement: str) -> tuple[tuple[str, ...], ...]:
        """Tags of every element of a placement of :data:`.parameters.ELEMENT_KINDS`, in the model's order.

        Bogies ``bogie1`` .. (1 leads), wheelsets ``ws1`` .., sides ``left``/``right``; the secondary
        elements of an articulated layout also name the carbody end they carry (``car1`` ..: a Jacobs bogie
        carries two). ``primary``: (bogie, wheelset, side); ``secondary``: (bogie[, car], side);
        ``yaw``: (bogie, side); ``bogie``: (bogie,).
        """
        out: list[tuple[str, ...]] = []
        for b in range(len(self.bogies)):
            bogie = f"bogie{b + 1}"
            if placement == "primary":
                out += [(bogie, f"ws{2 * b + w + 1}", side) for w in range(2) for side in SIDES]
            elif placement == "secondary":
                for c, _ in self.bogie_cars(b):
                    car = (f"car{c + 1}",) if self.articulated else ()
                    out += [(bogie, *car, side) for side in SIDES]
            elif placement == "yaw":
                out += [(bogie, side) for side in SIDES]
            elif placement == "bogie":
                out.append((bogie,))
            else:
                raise KeyError(f"unknown placement {placement!r}")
        return tuple(out)


SIDES = ("left", "right")
"""Side tags, side +1 (left, y > 0) first."""


SINGLE = Layout()
"""One car on two bogies."""


def layout_of(preset: str) -> Layout:
    """The layout of a vehicle preset (:data:`.parameters.LAYOUTS`: number of articulated carbodies, 0 for a
    conventional car). An articulated preset is a section from the middle of a rake: its end bogies also
    carry a neighbouring carbody end (``outer_neighbours``)."""
    n = P.LAYOUTS.get(preset, 0)
    return Layout(n, articulated=True, outer_neighbours=True) if n else SINGLE
