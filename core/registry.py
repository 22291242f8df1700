"""Plugin discovery and the registry of simulators, objectives and surrogates.

Loading is fixed and isolated (one broken plugin never takes the command line down):

1. every entry point of the group ``suspid`` is loaded on its own, sorted by
   name; a failure is a :class:`PluginWarning` naming the entry point and its
   distribution, and everything else keeps working;
2. ``SUSPID_STRICT_PLUGINS=1`` turns a load failure into a :class:`PluginError`;
3. ``SUSPID_DISABLE_PLUGINS=a,b`` blocks entry points by name;
4. ``SUSPID_DISABLE_PLUGIN_AUTOLOAD=1`` loads only suspid's own entry points
   (the test suite sets it, so a user's installed plugins cannot leak in);
5. ``check_pending()`` rejects hook implementations with misspelled names;
6. the ``register`` hooks are called one plugin at a time, so that two classes
   of one kind with one name are an error naming both providers.

Public API: :func:`get`, :func:`names`, :func:`plugins`, :func:`add_plugin`,
:func:`reset`.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any

import pluggy

from suspid import PROJECT_NAME, hookspecs
from suspid.errors import PluginError, UnknownPluginError

ENTRY_POINT_GROUP = PROJECT_NAME

KINDS: dict[str, str] = {
    "simulator": "suspid_register_simulators",
    "objective": "suspid_register_objectives",
    "surrogate": "suspid_register_surrogates",
    "optimizer": "suspid_register_optimizers",
    "executor": "suspid_register_executors",
    "effect": "suspid_register_effects",
    "reader": "suspid_register_readers",
}
"""Plugin kind -> the register hook that provides it."""


class PluginWarning(UserWarning):
    """A plugin could not be loaded; the run goes on without it."""


@dataclass
class PluginInfo:
    """Where one plugin (a module of hook implementations) comes from."""

    name: str
    module: str
    distribution: str | None = None
    version: str | None = None
    error: str | None = None
    classes: list[tuple[str, str]] = field(default_factory=list)  # (kind, name)


@dataclass
class Registered:
    """One registered class and the plugin that provided it."""

    kind: str
    name: str
    cls: type
    plugin: PluginInfo


def _env_flag(name: str) -> bool:
    return os.environ.get(name, "").strip().lower() in {"1", "true", "yes", "on"}


def _env_list(name: str) -> set[str]:
    return {s.strip() for s in os.environ.get(name, "").split(",") if s.strip()}


class Registry:
    """The loaded plugins and the classes they registered, by kind and name."""

    def __init__(self, extra_plugins: list[tuple[Any, str]] | None = None) -> None:
        self.strict = _env_flag("SUSPID_STRICT_PLUGINS")
        self.disabled = _env_list("SUSPID_DISABLE_PLUGINS")
        self.autoload = not _env_flag("SUSPID_DISABLE_PLUGIN_AUTOLOAD")
        self.pm = pluggy.PluginManager(PROJECT_NAME)
        self.pm.add_hookspecs(hookspecs)
        self.plugins: dict[str, PluginInfo] = {}
        self.failures: list[PluginInfo] = []
        self.classes: dict[str, dict[str, Registered]] = {kind: {} for kind in KINDS}
        self._load_entry_points()
        for obj, name in extra_plugins or []:
            self._register_plugin(obj, PluginInfo(name=name, module=getattr(obj, "__name__", repr(obj)),
                                                  distribution="(registered in code)"))
        self._collect()

    # -- loading ---------------------------------------------------------------
    def _fail(self, info: PluginInfo, exc: BaseException) -> None:
        info.error = f"{type(exc).__name__}: {exc}".splitlines()[0]
        self.failures.append(info)
        where = f" (distribution {info.distribution})" if info.distribution else ""
        message = f'Error importing plugin "{info.name}"{where}: {info.error}'
        if self.strict:
            raise PluginError(message + " [SUSPID_STRICT_PLUGINS=1]") from exc
        warnings.warn(message + "; continuing without it", PluginWarning, stacklevel=3)

    def _load_entry_points(self) -> None:
        eps = sorted(metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda ep: ep.name)
        for ep in eps:
            dist = ep.dist.name if ep.dist is not None else None
            info = PluginInfo(name=ep.name, module=ep.value, distribution=dist,
                              version=ep.dist.version if ep.dist is not None else None)
            if ep.name in self.disabled:
                continue
            if not self.autoload and (dist or "").lower() != PROJECT_NAME:
                continue
            if ep.name in self.plugins:
                other = self.plugins[ep.name]
                self._fail(info, PluginError(
                    f"entry point name '{ep.name}' is also used by distribution {other.distribution}"))
                continue
            try:
                obj = ep.load()
            except Exception as exc:  # any import-time failure of third-party code
                self._fail(info, exc)
                continue
            self._register_plugin(obj, info)

    def _register_plugin(self, obj: Any, info: PluginInfo) -> None:
        try:
            self.pm.register(obj, name=info.name)
            self.pm.check_pending()  # a misspelled suspid_* hook is this plugin's error
        except Exception as exc:
            if self.pm.is_registered(obj):
                self.pm.unregister(obj)
            self._fail(info, exc)
            return
        self.plugins[info.name] = info

    # -- collecting classes ----------------------------------------------------
    def _collect(self) -> None:
        for kind, hook_name in KINDS.items():
            caller = getattr(self.pm.hook, hook_name)
            for impl in reversed(caller.get_hookimpls()):  # registration order
                info = self.plugins[impl.plugin_name]
                try:
                    impl.function(register=self._register_callback(kind, info))
                except PluginError:
                    raise
                except Exception as exc:
                    self._fail(info, exc)

    def _register_callback(self, kind: str, info: PluginInfo):
        def register(cls: type) -> None:
            name = getattr(cls, "name", None)
            if not isinstance(name, str) or not name:
                raise PluginError(f'plugin "{info.name}" registered {kind} {cls!r} without a '
                                  f"string class attribute 'name'")
            existing = self.classes[kind].get(name)
            if existing is not None:
                raise PluginError(
                    f"{kind} '{name}' is registered twice: by plugin \"{existing.plugin.name}\" "
                    f"({existing.plugin.distribution}, {existing.cls.__module__}.{existing.cls.__qualname__}) "
                    f"and by plugin \"{info.name}\" ({info.distribution}, "
                    f"{cls.__module__}.{cls.__qualname__})")
            self.classes[kind][name] = Registered(kind, name, cls, info)
            info.classes.append((kind, name))
        return register

    # -- queries ---------------------------------------------------------------
    def get(self, kind: str, name: str) -> type:
        table = self._table(kind)
        if name not in table:
            available = ", ".join(sorted(table)) or "none"
            raise UnknownPluginError(
                f"{kind} '{name}' is not available (the plugin may not be installed); "
                f"available {kind}s: {available}")
        return table[name].cls

    def names(self, kind: str) -> list[str]:
        return sorted(self._table(kind))

    def _table(self, kind: str) -> dict[str, Registered]:
        if kind not in self.classes:
            raise PluginError(f"unknown plugin kind '{kind}'; kinds are {', '.join(KINDS)}")
        return self.classes[kind]


_registry: Registry | None = None
_extra_plugins: list[tuple[Any, str]] = []


def registry() -> Registry:
    """The process-wide registry, built on first use."""
    global _registry
    if _registry is None:
        _registry = Registry(list(_extra_plugins))
    return _registry


def get(kind: str, name: str) -> type:
    """The class registered as ``name`` for ``kind`` (``"simulator"``, ``"objective"``, ...).

    :raises UnknownPluginError: listing the available names.
    """
    return registry().get(kind, name)


def names(kind: str) -> list[str]:
    """Sorted names registered for ``kind``."""
    return registry().names(kind)


def plugins() -> tuple[list[Registered], list[PluginInfo]]:
    """Every registered class (sorted by kind and name) and the plugins that failed."""
    reg = registry()
    rows = [r for kind in KINDS for r in sorted(reg.classes[kind].values(), key=lambda r: r.name)]
    return rows, list(reg.failures)


def describe(kind: str, name: str) -> str:
    """``plugin 'name' (distribution D V, module M)``: who to tell when a plugin misbehaves."""
    row = registry().classes.get(kind, {}).get(name)
    if row is None:
        return f"{kind} plugin '{name}'"
    dist = " ".join(x for x in (row.plugin.distribution, row.plugin.version) if x) or "no distribution"
    return f"{kind} plugin '{name}' ({dist}, module {row.cls.__module__})"


def provider_of(module_names: list[str]) -> Registered | None:
    """The registered class whose module is the innermost of ``module_names`` (a traceback's modules,
    outermost first), or None when none of them belongs to a plugin."""
    rows = plugins()[0] if _registry is not None else []
    for module in reversed(module_names):
        for row in rows:
            home = row.plugin.module
            if module == home or module.startswith(home + ".") or module == row.cls.__module__:
                return row
    return None


def add_plugin(obj: Any, name: str) -> None:
    """Register a plugin object (a module or an instance with hook implementations) in code.

    Meant for tests and notebooks; the registry is rebuilt on next use.
    """
    _extra_plugins.append((obj, name))
    reset(keep_extra=True)


def reset(keep_extra: bool = False) -> None:
    """Forget the loaded plugins; the next query loads them again (re-reading the environment)."""
    global _registry
    _registry = None
    if not keep_extra:
        _extra_plugins.clear()
