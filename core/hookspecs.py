"""Hook specifications: the whole contract between suspid and its plugins.

A plugin is a module (or object) with functions marked ``@suspid.hookimpl``
whose names match the specifications below. It is found through the
entry-point group ``suspid``; the built-in plugins come through the same
group, declared in suspid's own ``pyproject.toml``.

Every hook here is a ``register`` hook: it receives a callback and calls it
once per class it provides. Classes are keyed by their class attribute
``name`` (``name = "exudyn-train"``); two classes of one kind with the same
name are a startup error that names both providers. Hooks evolve by gaining
arguments only: an implementation may accept a subset of them.
"""

from __future__ import annotations

from typing import Callable

import pluggy

PROJECT_NAME = "suspid"
"""The pluggy project name; it builds both markers and names the entry-point group."""

hookspec = pluggy.HookspecMarker(PROJECT_NAME)
"""Marks the specifications below."""

hookimpl = pluggy.HookimplMarker(PROJECT_NAME)
"""Marks a plugin's implementations; re-exported as ``suspid.hookimpl``."""

Register = Callable[[type], None]
"""``register(cls)``: add one class to the registry of the hook's kind."""


@hookspec
def suspid_register_simulators(register: Register) -> None:
    """Register simulator backends.

    Called once, when the registry is first used (``suspid.registry``), after
    every plugin has been loaded.

    :param register: call ``register(cls)`` for each simulator class. ``cls``
        subclasses :class:`suspid.interfaces.Simulator` and has a unique
        ``name``; configs select it as ``simulator: {plugin: <name>}``.
    :returns: nothing; the return value is ignored.
    """


@hookspec
def suspid_register_objectives(register: Register) -> None:
    """Register objective functions Ψ_k (paper eq. 5-8).

    Called once, when the registry is first used, after every plugin is loaded.

    :param register: call ``register(cls)`` for each objective class. ``cls``
        subclasses :class:`suspid.interfaces.Objective` and has a unique
        ``name``; configs select it as ``objective: {plugin: <name>}``.
    :returns: nothing; the return value is ignored.
    """


@hookspec
def suspid_register_surrogates(register: Register) -> None:
    """Register surrogate models (metamodels of J for EGO, paper §3.2).

    Called once, when the registry is first used, after every plugin is loaded.

    :param register: call ``register(cls)`` for each surrogate class. ``cls``
        subclasses :class:`suspid.interfaces.Surrogate` and has a unique
        ``name``; configs select it as ``surrogate: {plugin: <name>}``.
    :returns: nothing; the return value is ignored.
    """


@hookspec
def suspid_register_optimizers(register: Register) -> None:
    """Register optimisers: who chooses the points where J is evaluated (the paper's EGO and others).

    Called once, when the registry is first used, after every plugin is loaded.

    :param register: call ``register(cls)`` for each optimiser class. ``cls``
        subclasses :class:`suspid.interfaces.Optimizer` (an ask/tell object) and
        has a unique ``name``; configs select it as ``optimizer: {plugin: <name>}``.
    :returns: nothing; the return value is ignored.
    """


@hookspec
def suspid_register_executors(register: Register) -> None:
    """Register executors: where the simulator calls of a run are carried out.

    Called once, when the registry is first used, after every plugin is loaded.

    :param register: call ``register(cls)`` for each executor class. ``cls``
        subclasses :class:`suspid.interfaces.Executor` and has a unique
        ``name``; configs select it as ``executor: {plugin: <name>}``.
    :returns: nothing; the return value is ignored.
    """


@hookspec
def suspid_register_effects(register: Register) -> None:
    """Register model effects: named extensions missing from rigid models (discrepancy workflow).

    Called once, when the registry is first used, after every plugin is loaded.

    :param register: call ``register(cls)`` for each effect class. ``cls``
        subclasses :class:`suspid.interfaces.Effect` and has a unique ``name``;
        configs enable it as ``simulator.options.effects: [{name: <name>, ...}]``
        for simulators that support it.
    :returns: nothing; the return value is ignored.
    """


@hookspec
def suspid_register_readers(register: Register) -> None:
    """Register recording readers: one per file format of a data-acquisition system (``suspid ingest``).

    Called once, when the registry is first used, after every plugin is loaded.

    :param register: call ``register(cls)`` for each reader class. ``cls``
        subclasses :class:`suspid.interfaces.Reader`, has a unique ``name`` and
        lists the file ``extensions`` it reads; ingest configs select it as
        ``recording: {format: <name>}`` or by the file's extension.
    :returns: nothing; the return value is ignored.
    """
