"""The ``diagnose:`` section of a config: its options and their validation."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, ValidationError

from suspid.config import Config, Section, raise_validation_error


class DiagnoseOptions(Section):
    """The ``diagnose:`` section of a config."""

    at: Literal["identified", "nominal"] = Field(
        default="identified", description="base model: identified parameters (a run first) or nominal ones")
    bands_per_octave: float = Field(default=3.0, gt=0.0, le=24.0, description="band width: 1/bands_per_octave octave")
    min_bins_per_band: int = Field(default=3, ge=1, description="least grid frequencies per band (merged upwards)")
    alpha: float = Field(default=0.05, gt=0.0, lt=1.0, description="false discovery rate (Benjamini-Yekutieli)")
    n_bootstrap: int = Field(default=200, ge=0, description="parametric bootstrap replicates of the null (0: analytic)")
    effects: list[str] | None = Field(default=None, description="candidate effects (default: every registered "
                                      "effect the simulator supports)")
    margin: float = Field(default=10.0, ge=0.0, description="score margin over the runner-up and the bump to name")
    min_explained: float = Field(default=0.5, ge=0.0, le=1.0,
                                 description="share of the flagged cells' discrepancy the named effect must explain")
    n_starts: int = Field(default=2, ge=1, description="starting points refined per effect")
    max_evaluations: int = Field(default=30, ge=3, description="simulator calls per refinement")
    reidentify: bool = Field(default=True, description="run the identification again with the named effect")


def diagnose_options(config: Config) -> DiagnoseOptions:
    """The validated ``diagnose:`` section; an error names the file and the key, worded like every config error."""
    try:
        return DiagnoseOptions.model_validate(config.diagnose)
    except ValidationError as exc:
        raise_validation_error(exc, DiagnoseOptions, str(config.source_file), {}, ("diagnose",))
