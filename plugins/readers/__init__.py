"""Built-in recording readers for ``suspid ingest``: one module per file format.

| name | extensions | library |
| --- | --- | --- |
| ``mdf4`` | ``.mf4``, ``.mdf`` | asammdf (extra ``ingest``) |
| ``mat`` | ``.mat`` (v5 through scipy.io, v7.3 through h5py) | scipy, h5py |
| ``tdms`` | ``.tdms`` | npTDMS (extra ``ingest``) |
| ``csv`` | ``.csv``, ``.txt`` | numpy |
| ``hdf5`` | ``.h5``, ``.hdf5`` | h5py |

The libraries of the optional formats are imported when such a file is
opened, not when this plugin loads: a user without the ``ingest`` extra keeps
every other command and reader, and opening an ``.mf4`` file then says which
package to install.
"""

from __future__ import annotations

from suspid import hookimpl

from .delimited import CsvReader
from .hdf5 import Hdf5Reader
from .mat import MatReader
from .mdf4 import Mdf4Reader
from .tdms import TdmsReader

READERS = (Mdf4Reader, MatReader, TdmsReader, CsvReader, Hdf5Reader)


@hookimpl
def suspid_register_readers(register):
    """Register the five built-in readers (mdf4, mat, tdms, csv, hdf5)."""
    for cls in READERS:
        register(cls)
