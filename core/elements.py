"""Element-level parameters: the physical elements a simulator declares and the groups a config may tie.

A simulator that models its suspension element by element (every yaw damper,
lateral damper, air spring, primary element, each on its bogie, end and side)
declares those elements through the optional capability
:class:`suspid.interfaces.ElementSimulator`. Each :class:`~suspid.interfaces.Element`
has a *kind* (the parameter that sets every element of that kind today, e.g.
``c_yaw``) and *tags* (where it sits, e.g. ``("bogie1", "left")``).

**Group syntax.** ``kind[tag,tag,...]`` names the elements of ``kind`` that
carry every listed tag: ``c_yaw[bogie1]`` is both yaw dampers of bogie 1,
``c_yaw[bogie1,left]`` one damper, ``c_yaw[left]`` the left dampers of every
bogie; the bare kind ``c_yaw`` is all of them (the kind-level parameter, the
default). Tag order does not matter; a group's canonical name lists its tags
in the order of the elements' tags. A group's value is the SI value of every
element in it; elements no named group covers keep the kind's value.

A config may name groups wherever it names parameters (``parameters:``,
``data.w_ref``); :func:`check_groups` refuses an unknown group (one line naming
the key and the kind's groups) and two groups of one kind that share an
element (their values would compete). Simulators without the capability are
unchanged: their parameter names are plain names.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from typing import Iterable, Mapping, Sequence

from suspid.interfaces import Element, ElementSimulator, Parameter

__all__ = ["ElementGroup", "parse_group", "split_name", "declared_groups", "group_members", "resolve_group",
           "group_parameters", "declared_parameters", "check_groups", "kind_of", "finest_groups"]


@dataclass(frozen=True)
class ElementGroup:
    """A set of elements of one kind tied to one value.

    :ivar name: canonical name, ``kind`` or ``kind[tag,...]``.
    :ivar kind: the kind-level parameter's name.
    :ivar tags: the selecting tags (empty: the whole kind).
    :ivar members: the selected elements' tag tuples, in declaration order.
    """

    name: str
    kind: str
    tags: tuple[str, ...]
    members: tuple[tuple[str, ...], ...]

    def overlaps(self, other: "ElementGroup") -> bool:
        """True when both groups are of one kind and share an element."""
        return self.kind == other.kind and bool(set(self.members) & set(other.members))


def split_name(name: str) -> tuple[str, tuple[str, ...]] | None:
    """``"c_yaw[bogie1, left]"`` -> ``("c_yaw", ("bogie1", "left"))``; a plain name -> ``(name, ())``;
    ``None`` for a malformed bracket (no closing bracket, empty tag list, text after it)."""
    if "[" not in name and "]" not in name:
        return name, ()
    if not name.endswith("]") or name.count("[") != 1 or name.count("]") != 1:
        return None
    kind, rest = name[:-1].split("[", 1)
    tags = tuple(t.strip() for t in rest.split(","))
    if not kind.strip() or not all(tags):
        return None
    return kind.strip(), tags


def kind_of(name: str) -> str:
    """The kind of a group name (the name itself for a plain parameter)."""
    return name.split("[", 1)[0].strip()


def _group_name(kind: str, tags: Sequence[str]) -> str:
    return f"{kind}[{','.join(tags)}]" if tags else kind


def group_members(elements: Sequence[Element], kind: str, tags: Iterable[str]) -> tuple[tuple[str, ...], ...]:
    """The tag tuples of the elements of ``kind`` that carry every tag of ``tags``."""
    want = set(tags)
    return tuple(e.tags for e in elements if e.kind == kind and want <= set(e.tags))


def declared_groups(elements: Sequence[Element]) -> dict[str, ElementGroup]:
    """Every group a config may name, canonical name -> group: per kind, the kind itself and each
    combination of tags that some element carries, one name per distinct set of members (the shortest
    combination, first in tag order, keeps the name: ``c_sec_y[car1]`` is not listed when it selects what
    ``c_sec_y`` selects)."""
    out: dict[str, ElementGroup] = {}
    seen: dict[tuple[str, frozenset], str] = {}
    kinds = list(dict.fromkeys(e.kind for e in elements))
    for kind in kinds:
        mine = [e for e in elements if e.kind == kind]
        candidates: list[tuple[str, ...]] = [()]
        for size in range(1, max(len(e.tags) for e in mine) + 1):
            for e in mine:
                for combo in itertools.combinations(e.tags, size):
                    if combo not in candidates:
                        candidates.append(combo)
        for combo in candidates:
            members = group_members(elements, kind, combo)
            key = (kind, frozenset(members))
            if not members or key in seen:
                continue
            name = _group_name(kind, combo)
            seen[key] = name
            out[name] = ElementGroup(name, kind, tuple(combo), members)
    return out


def resolve_group(elements: Sequence[Element], name: str) -> ElementGroup | None:
    """The group ``name`` selects (tags in any order), named canonically; ``None`` when ``name`` is not of the
    group syntax, its kind has no declared element or its tags select none."""
    parts = split_name(name)
    if parts is None:
        return None
    kind, tags = parts
    if not any(e.kind == kind for e in elements):
        return None
    members = group_members(elements, kind, tags)
    if not members:
        return None
    for g in declared_groups(elements).values():
        if g.kind == kind and set(g.members) == set(members):
            return g
    return None   # pragma: no cover - every non-empty member set is declared


def finest_groups(elements: Sequence[Element], kinds: Sequence[str] | None = None) -> list[ElementGroup]:
    """One group per element (its full tags), for ``kinds`` (default: every declared kind), in order."""
    groups = declared_groups(elements)
    want = list(dict.fromkeys(e.kind for e in elements)) if kinds is None else list(kinds)
    out = []
    for kind in want:
        for e in elements:
            if e.kind == kind:
                g = resolve_group(elements, _group_name(kind, e.tags))
                if g is not None and g.name in groups and len(g.members) == 1:
                    out.append(g)
    return out


def group_parameters(simulator, kind_parameters: Mapping[str, Parameter] | None = None) -> list[Parameter]:
    """A :class:`~suspid.interfaces.Parameter` for every declared group that is not a kind itself (unit,
    nominal, bounds and domain of its kind; the description says which elements it ties)."""
    if not isinstance(simulator, ElementSimulator):
        return []
    known = dict(kind_parameters) if kind_parameters is not None else {p.name: p for p in simulator.parameters()}
    out = []
    for g in declared_groups(simulator.elements()).values():
        if not g.tags or g.kind not in known:
            continue
        k = known[g.kind]
        out.append(replace(k, name=g.name, description=f"{len(g.members)} element(s) of {g.kind} "
                                                        f"({'; '.join(','.join(m) for m in g.members)}): "
                                                        f"{k.description}"))
    return out


def declared_parameters(simulator) -> list[Parameter]:
    """:meth:`Simulator.parameters` and, for an :class:`~suspid.interfaces.ElementSimulator`, a parameter per
    declared element group (:func:`group_parameters`): every name a config may identify."""
    params = simulator.parameters()
    return params + group_parameters(simulator, {p.name: p for p in params})


def check_groups(simulator, names: Sequence[str], where: str = "parameters") -> list[tuple[str, str]]:
    """Problems with the element groups among ``names``, as ``(name, message)`` pairs (empty: fine).

    A name with brackets must select elements the simulator declares (message: the kind's groups); two
    names of one kind must not share an element (message: both names). Plain names are not checked here.
    """
    problems: list[tuple[str, str]] = []
    elements = simulator.elements() if isinstance(simulator, ElementSimulator) else []
    groups = declared_groups(elements)
    resolved: list[tuple[str, ElementGroup]] = []
    for name in names:
        parts = split_name(name)
        if parts is None:
            problems.append((name, f"malformed element group '{name}': expected kind[tag,tag,...], "
                                   f"e.g. c_yaw[bogie1,left]"))
            continue
        kind, tags = parts
        if not tags:
            if kind in {e.kind for e in elements}:
                resolved.append((name, groups[kind]))
            continue
        if not elements:
            problems.append((name, f"simulator '{simulator.name}' declares no elements: element groups such as "
                                   f"'{name}' are not available"))
            continue
        g = resolve_group(elements, name)
        if g is None:
            same = [n for n, gg in groups.items() if gg.kind == kind]
            kinds = sorted({e.kind for e in elements})
            hint = (f"groups of {kind}: {', '.join(same)}" if same else
                    f"kinds with elements: {', '.join(kinds)}")
            problems.append((name, f"unknown element group '{name}' for simulator '{simulator.name}'; {hint}"))
            continue
        resolved.append((name, g))
    for (a, ga), (b, gb) in itertools.combinations(resolved, 2):
        if ga.overlaps(gb):
            shared = sorted(set(ga.members) & set(gb.members))
            problems.append((b, f"element groups '{a}' and '{b}' in {where} share element(s) "
                                f"{'; '.join(','.join(m) for m in shared)}: each element takes one value; name "
                                f"disjoint groups (available for {ga.kind}: "
                                f"{', '.join(n for n, g in groups.items() if g.kind == ga.kind)})"))
    return problems


def parse_group(simulator, name: str) -> ElementGroup:
    """The group ``name`` of ``simulator``.

    :raises KeyError: ``name`` is not a declared group (message: the kind's groups).
    """
    problems = check_groups(simulator, [name])
    if problems:
        raise KeyError(problems[0][1])
    elements = simulator.elements() if isinstance(simulator, ElementSimulator) else []
    g = resolve_group(elements, name)
    if g is None:
        raise KeyError(f"'{name}' is not an element group of simulator '{simulator.name}'")
    return g
