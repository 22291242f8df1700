"""A run's data identity from its inputs, not from arrays this machine computed.

The ledger keys every expensive result by what determines it. J(w) on a run's data
depends, beyond the simulator and w, on the measured spectra y_mes, the noise model B
and its paths b_i, the channel weights α and the objective. Those are arrays computed
here: spectra by FFT, B by least squares, α by a small optimisation. Another processor
(another BLAS kernel, another SIMD path of numpy's transcendental functions) gives them
with other last bits, so a key hashing them changes when a run folder moves to another
machine and every evaluation would be simulated again. The identities here hash what
those arrays are computed *from* instead:

- files by their bytes (:func:`file_digest`): measured records and track geometry, the
  reference date's records, a noise model file; never their absolute path, so that a
  project moved to another folder or machine keeps its keys;
- a numerical experiment by its config and seed (the track, the reference and
  measurement options, the simulator's identity), which fix every draw;
- options by their validated values (spectra, noise, objective, weights).

Four identities compose the run's data identity (:func:`data_identities`):

- ``reference``: what the reference date's spectra are made of (its measured files, or
  the experiment's track, reference options and seed); the reference-date self-check is
  keyed by it, so that it is shared by every measurement date of one reference date;
- ``noise``: what B is (a noise model file's bytes, or the reference identity and the
  noise options);
- ``weights``: what α is chosen from (the objective's weights; with ``reference`` or
  ``efficient``, the noise identity and, for ``efficient``, the identified parameters and
  the sampling options);
- ``data``: the measurement date's inputs with the two above, the objective and its
  options, the noise draws and the spectra options: the ``data_identity`` of every
  evaluation key.

Ledgers written before these identities keyed by array digests
(:func:`legacy_data_identity`); the lookups try those keys too (``Ledger.get_migrating``),
so an old ledger resumes on the machine that wrote it, and the trials of its run are
matched by trial id elsewhere (:mod:`suspid.workflows.driver`).
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from suspid.config import Config
from suspid.infra.ledger import stable_hash

__all__ = ["DataIdentities", "data_identities", "file_digest", "array_digest", "legacy_data_identity"]

IDENTITY_VERSION = "inputs-1"
"""Tag of the input-based identities (part of every hash below): changed only when what they cover changes."""

_DIGESTS: dict[tuple[str, int, int], str] = {}
"""File digests computed by this process, keyed by (absolute path, size, mtime in ns)."""


def _one_file(path: Path) -> str:
    st = path.stat()
    memo = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if memo not in _DIGESTS:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
        _DIGESTS[memo] = h.hexdigest()
    return _DIGESTS[memo]


def file_digest(path: str | Path | None) -> str | None:
    """The SHA-256 of a file's bytes; of a folder, of every file under it that is not hidden (a name that
    starts with ``.``), each by its path relative to the folder and its bytes. None for None.

    The path itself does not enter: a folder moved or copied elsewhere keeps its digest.
    """
    if path is None:
        return None
    p = Path(path)
    if p.is_file():
        return _one_file(p)
    entries = []
    for root, dirs, files in os.walk(p):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        for name in sorted(files):
            if not name.startswith("."):
                f = Path(root) / name
                entries.append([f.relative_to(p).as_posix(), _one_file(f)])
    return stable_hash("folder", entries)


def array_digest(*arrays: np.ndarray) -> str:
    """A content hash of arrays (shape, dtype and bytes): for arrays read from files or drawn from a seed,
    never for arrays computed by BLAS, FFT or vectorised transcendental functions (module docstring)."""
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str((a.shape, a.dtype.str)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


@dataclass(frozen=True)
class DataIdentities:
    """The input identities of a run's data (module docstring): hex digests."""

    reference: str
    noise: str
    weights: str
    data: str


def _reading(config: Config) -> dict[str, Any]:
    """The options with which measured files are read (they change what the arrays are)."""
    d = config.data
    return {"strict": d.strict, "accept": list(d.accept)}


def _reference_inputs(config: Config, simulator_identity: Any) -> list[Any]:
    """What the reference date's spectra (y_mes0, y_sim0) are made of; none without a reference date."""
    spectra = config.spectra.model_dump(mode="json")
    if config.data.source == "experiment":
        d = config.data
        return ["experiment", simulator_identity, config.seed, d.track.model_dump(mode="json"),
                d.reference.model_dump(mode="json"),
                d.track_band.model_dump(mode="json") if d.track_band is not None else None, spectra]
    ref = config.noise.reference
    if ref is None:
        return ["none"]
    return ["measured", simulator_identity, file_digest(ref.measurements), file_digest(ref.track_file),
            _reading(config), spectra]


def _noise_inputs(config: Config, reference: str) -> list[Any]:
    """What B is: a noise model file's bytes (it takes precedence over a reference date), else the reference
    date and the noise options it is identified with."""
    if config.noise.path is not None:
        return ["file", file_digest(config.noise.path)]
    return ["identified", reference, config.noise.model_dump(mode="json", exclude={"path", "reference"})]


def _measurement_inputs(config: Config, simulator_identity: Any) -> list[Any]:
    d = config.data
    spectra = config.spectra.model_dump(mode="json")
    if d.source == "experiment":
        return ["experiment", simulator_identity, config.seed,
                d.model_dump(mode="json", exclude={"measurements", "track_file"}), spectra]
    return ["measured", file_digest(d.measurements), file_digest(d.track_file), _reading(config),
            [c.model_dump(mode="json") for c in d.corrections],
            d.track_band.model_dump(mode="json") if d.track_band is not None else None, spectra]


def data_identities(config: Config, simulator_identity: Any, names: Sequence[str], bounds: np.ndarray
                    ) -> DataIdentities:
    """The noise, weights and data identities of a run (module docstring).

    :param names: the identified parameters ``(q,)``; :param bounds: ``(q, 2)`` SI (from the config and the
        simulator's declarations, not computed): they enter the weights identity with ``efficient`` weights,
        which are chosen at w0 by simulations within these bounds.
    """
    reference = stable_hash(IDENTITY_VERSION, "reference", _reference_inputs(config, simulator_identity))
    noise = stable_hash(IDENTITY_VERSION, "noise", _noise_inputs(config, reference))
    objective = config.objective
    weights_parts: list[Any] = [objective.weights]
    if objective.weights in ("reference", "efficient"):
        weights_parts.append(noise)
    if objective.weights == "efficient":
        ident = config.identifiability
        weights_parts += [reference, objective.plugin, objective.options, list(names),
                          np.asarray(bounds, float).tolist(), ident.step, ident.n_redraws, ident.bootstrap]
    weights = stable_hash(IDENTITY_VERSION, "weights", weights_parts)
    data = stable_hash(IDENTITY_VERSION, "data", _measurement_inputs(config, simulator_identity), noise, weights,
                       objective.plugin, objective.options, objective.noise_draws, config.seed)
    return DataIdentities(reference=reference, noise=noise, weights=weights, data=data)


def legacy_data_identity(y_mes: np.ndarray, b: np.ndarray, b_more: np.ndarray | None, segments_digest: str,
                         config: Config, alpha: np.ndarray) -> str:
    """The data identity ledgers written before :data:`IDENTITY_VERSION` keyed J by (array digests of y_mes
    and the paths, α's values): only to find their results, on the machine family that computed them."""
    return stable_hash("data", array_digest(y_mes, b, *([] if b_more is None else [b_more])), segments_digest,
                       config.objective.plugin, config.objective.options, np.asarray(alpha).tolist(),
                       config.spectra.model_dump())
