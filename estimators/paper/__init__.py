"""The paper's evaluation (``quadfault reproduce``): the flights, the EKF calibration, the
scores, ``metrics.json``, ``report.md`` and the figures.

* :mod:`estimators.paper.reproduce` -- the study and the ``quadfault reproduce`` command;
* :mod:`estimators.paper.calibration` -- the EKF's ``Q_eta`` matched to the IRLS RMSE, and
  the calibration of the EKF's reported uncertainty;
* :mod:`estimators.paper.report` and :mod:`estimators.paper.figures` -- the outputs.
"""
