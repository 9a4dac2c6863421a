"""The outcome of a BRDF fit: parameters, uncertainties, error, and why it failed if it did."""
import json
import math
from dataclasses import dataclass, field

import numpy as np

import facette.brdf

__all__ = ["FitResult"]


def _clean(x):
    """JSON-safe: non-finite floats become null (never a silent NaN in brdf.json)."""
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_clean(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    return x


@dataclass
class FitResult:
    """Result of ``facette.fit.fit_brdf`` (and the two fitters).

    success : the optimiser converged to finite parameters that explain the data.
    message : why it failed, or notes (parameters at a bound, samples dropped, model choice).
    model, distribution, masking, volume, interreflection : the model fitted.
    params : {"kd": [C floats], "sigma": float, "n_i": float} (those the model has).
    uncertainties : same keys, one standard deviation from the Jacobian (None if singular).
    error : {"rms": 1/sr, "relative_rms": rms / rms(data), "n_samples", "n_channels"}.
    method : "least_squares" | "genetic"; time_s : wall time; n_evaluations : model evaluations.
    selection : notes of the model selection (which simpler models were tried, and why chosen).
    verdict : "" (not judged), "fits" or "no model fits well" (`facette.fit.fit_cells_verdict`);
    models_tried : one dict per model fitted for the verdict (model, relative_rms, parameters).
    """
    success: bool
    message: str
    model: str
    params: dict
    uncertainties: dict
    error: dict
    method: str
    distribution: str = None
    masking: str = None
    volume: str = None
    interreflection: bool = False
    time_s: float = 0.0
    n_evaluations: int = 0
    selection: list = field(default_factory=list)
    verdict: str = ""
    models_tried: list = field(default_factory=list)

    def brdf_params(self):
        """Keyword arguments for ``facette.brdf.get(self.model)``."""
        kw = {"kd": list(self.params.get("kd", []))}
        for k in ("sigma", "n_i"):
            if k in self.params:
                kw[k] = self.params[k]
        if self.model in ("li", "cook_torrance"):
            kw.update(distribution=self.distribution, masking=self.masking)
        if self.model == "li":
            kw.update(volume=self.volume, interreflection=self.interreflection)
        return kw

    def predict(self, s, o):
        """Model values (..., C) at directions s, o (..., 3) with the fitted parameters."""
        if not self.success and not self.params:
            raise ValueError(f"this fit failed ({self.message}); it has no parameters to evaluate")
        return facette.brdf.get(self.model)(s, o, **self.brdf_params())

    def to_dict(self):
        d = {"schema": 1, "model": self.model, "distribution": self.distribution, "masking": self.masking,
             "volume": self.volume, "interreflection": self.interreflection,
             "parameters": self.params, "uncertainties": self.uncertainties, "fit_error": self.error,
             "success": self.success, "message": self.message, "method": self.method,
             "time_s": self.time_s, "n_evaluations": self.n_evaluations, "selection": self.selection}
        if self.verdict:
            d.update(verdict=self.verdict, models_tried=self.models_tried)
        return _clean(d)

    def to_json(self, indent=2):
        """brdf.json text: model, distribution, masking, parameters per channel, uncertainties, fit error."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    def __str__(self):
        p = ", ".join(f"{k}={np.round(v, 4).tolist()}" for k, v in self.params.items())
        state = ("FAILED" if not self.success else "NO MODEL FITS WELL" if self.verdict == "no model fits well"
                 else "ok")
        return f"{self.model}({p}) [{state}: {self.message}]"
