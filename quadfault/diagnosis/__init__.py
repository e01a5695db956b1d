"""Model-mismatch diagnosis (method: docs/diagnosis.md; result format: docs/formats.md).

``Diagnosis(DiagnosisConfig()).fit(recording, vehicle=None) -> DiagnosisResult``: replay the
recording through the nominal model, locate where and in which regime it disagrees, fit a
library of physically named effects (:mod:`quadfault.model.effects`) by bounded robust least
squares, and keep those that improve held-out residuals (time-blocked cross-validation + BIC).

Modules: ``residuals`` (replay and block-mean channels), ``library`` (candidate effects),
``fit`` (optimizer), ``select`` (forward selection), ``rivals`` (rival explanations as whole
sets, held-out support), ``findings`` (the reported effects), ``locate`` (intervals and regimes),
``prediction`` (open-loop multi-step), ``result`` (record and JSON), ``report`` (markdown and
plots), ``cli`` (``quadfault diagnose``).
"""

from quadfault.diagnosis.diagnose import Diagnosis, DiagnosisConfig
from quadfault.diagnosis.result import DiagnosisResult, EffectFinding, Interval

__all__ = ["Diagnosis", "DiagnosisConfig", "DiagnosisResult", "EffectFinding", "Interval"]
