"""The estimator registry: one table of every estimator by name, and the one factory.

Every place that chooses an estimator by name -- ``quadfault estimate --estimator``,
``quadfault reproduce``, the environments' ``estimator=``, the vector environment, the agents'
rollouts -- looks it up here and builds it with :func:`make_estimator`. A row of
:data:`TABLE` (an :class:`EstimatorSpec`) says where the estimator's class lives, its
configuration class, its batched form (N estimators updated together, for the vector
environment), the ``quadfault estimate`` options its configuration takes, and what it reads.
Classes are imported only when chosen (``"module:Class"`` strings), so this module imports
nothing heavy and a missing optional estimator is a one-line error, not an ImportError.

Adding an estimator: write its module (the interface of :class:`estimators.base.OnlineEstimator`)
and add one row to :data:`TABLE` (docs/estimators.md, "Adding an estimator").
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from quadfault.errors import ConfigError

#: what a registered entry is: a real estimator (reads measurements only), the nominal belief
#: (estimates nothing), or the labelled oracle (reads the true efficiency schedule)
ROLES = ("estimator", "nominal", "oracle")
#: the options of ``quadfault estimate`` a configuration may take (``Config.from_options``)
OPTIONS = ("improved", "median", "q_eta", "forgetting", "prefilter", "accelerometer")


@dataclass(frozen=True)
class EstimatorSpec:
    """One row of the registry.

    Attributes:
        name: the name users choose (``--estimator``, ``estimator=``).
        online: ``"module:Class"``; ``Class(vehicle, config=None)`` implements
            :class:`estimators.base.OnlineEstimator` (``reset``, ``update(sample) ->
            Estimate``, ``run(recording) -> EstimateSeries``).
        summary: one line for ``--help`` and the docs.
        config: ``"module:Class"`` of its configuration (a frozen dataclass), or None.
        batched: ``"module:Class"`` of its batched form, ``Class(vehicle, num, config=None)``
            with ``reset(mask=None, eta0=None)`` and ``update(t, p, v, R, w, f) ->
            BatchedEstimate`` (:mod:`estimators.batched`), or None (then the vector
            environment does not offer it).
        options: the ``quadfault estimate`` options its configuration takes, among
            :data:`OPTIONS`; the configuration class builds itself from them with
            ``from_options(**given)``. ``median`` here means the estimator's own online output
            median; the others get ``--median`` as post-processing of their output.
        role: one of :data:`ROLES`.
        needs: what it reads from a recording or sample: ``"pose"`` (position, velocity,
            attitude, rate), ``"commands"`` (rotor thrust commands), ``"truth"`` (the true
            efficiency schedule, the oracle only).
    """

    name: str
    online: str
    summary: str
    config: str | None = None
    batched: str | None = None
    options: tuple[str, ...] = ()
    role: str = "estimator"
    needs: tuple[str, ...] = ("pose", "commands")


#: every estimator, in the order the command line and the docs list them
TABLE: tuple[EstimatorSpec, ...] = (
    EstimatorSpec(
        "irls",
        "estimators.irls:SlidingWindowIRLS",
        "the paper's sliding-window IRLS (default)",
        config="estimators.irls_config:IRLSConfig",
        batched="estimators.batched:BatchedIRLS",
        options=("improved", "median", "prefilter", "accelerometer"),
    ),
    EstimatorSpec(
        "ekf",
        "estimators.ekf:MotorEfficiencyEKF",
        "extended Kalman filter over the rigid body and the efficiencies (baseline)",
        config="estimators.ekf:EKFConfig",
        batched="estimators.batched:BatchedEKF",
        options=("q_eta", "accelerometer"),
    ),
    EstimatorSpec(
        "rls",
        "estimators.rls:RecursiveLeastSquares",
        "recursive least squares with a forgetting factor on the IRLS's regression "
        "(what INDI controllers fly; baseline)",
        config="estimators.rls:RLSConfig",
        batched="estimators.rls:BatchedRLS",
        options=("forgetting", "prefilter", "accelerometer"),
    ),
    EstimatorSpec(
        "ukf",
        "estimators.ukf:UnscentedKalmanFilter",
        "unscented Kalman filter over velocity, rate and the efficiencies (baseline)",
        config="estimators.ukf:UKFConfig",
        batched="estimators.ukf:BatchedUKF",
        options=("q_eta", "accelerometer"),
    ),
    EstimatorSpec(
        "none",
        "estimators.baselines:NominalBelief",
        "no estimator: eta = 1 with a fixed prior uncertainty",
        role="nominal",
        needs=(),
    ),
    EstimatorSpec(
        "truth",
        "estimators.baselines:TruthOracle",
        "the labelled oracle: the true efficiency schedule (environments, rollouts)",
        role="oracle",
        needs=("truth",),
    ),
)

#: name -> row of :data:`TABLE`
ESTIMATORS: dict[str, EstimatorSpec] = {spec.name: spec for spec in TABLE}


def estimator_names(role: str | None = None, batched: bool | None = None) -> tuple[str, ...]:
    """The registered names, optionally only those of ``role`` and / or those with
    (``batched=True``) or without a batched form."""
    return tuple(
        s.name
        for s in ESTIMATORS.values()
        if (role is None or s.role == role)
        and (batched is None or (s.batched is not None) == batched)
    )


def estimator_spec(name) -> EstimatorSpec:
    """The row of ``name`` (a one-line error naming the choices when unknown)."""
    if not isinstance(name, str) or name not in ESTIMATORS:
        raise ConfigError(f"unknown estimator {name!r}; choose from {', '.join(ESTIMATORS)}")
    return ESTIMATORS[name]


def _load(name: str, entry: str):
    """The class at ``"module:Class"`` (a one-line error when its module is missing)."""
    module_name, class_name = entry.split(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name is None or not module_name.startswith(exc.name):
            raise  # a missing dependency inside the module: its own error
        raise ConfigError(f"estimator {name!r} is not available ({entry}: {exc})") from None
    try:
        return getattr(module, class_name)
    except AttributeError:
        raise ConfigError(
            f"estimator {name!r} is not available ({module_name} has no {class_name})"
        ) from None


def estimator_class(name: str, batched: bool = False):
    """The class registered under ``name`` (its batched form with ``batched=True``)."""
    spec = estimator_spec(name)
    if batched:
        if spec.batched is None:
            raise ConfigError(
                f"estimator {name!r} has no batched form; batched estimators: "
                f"{', '.join(estimator_names(batched=True))}"
            )
        return _load(name, spec.batched)
    return _load(name, spec.online)


def config_class(name: str):
    """The configuration class of ``name``, or None when it takes no configuration."""
    spec = estimator_spec(name)
    return None if spec.config is None else _load(name, spec.config)


def config_from_options(name: str, **options):
    """The configuration of ``name`` built from ``quadfault estimate`` options (``None`` /
    ``False`` values mean "not given"); None when no option is given."""
    spec = estimator_spec(name)
    given = {k: v for k, v in options.items() if v is not None and v is not False}
    if not given:
        return None
    for key in given:
        if key not in spec.options:
            takers = [s.name for s in TABLE if key in s.options]
            raise ConfigError(
                f"option {key!r} applies to the {', '.join(takers) or 'no'} estimator, not {name!r}"
            )
    return config_class(name).from_options(**given)


def make_estimator(name, vehicle, config=None, *, num: int | None = None, schedule=None, **options):
    """Build the estimator registered under ``name`` for the *nominal* ``vehicle``.

    Args:
        name: a registered name, or an estimator object (anything with ``reset`` and
            ``update``), returned as it is.
        config: its configuration (the class of :attr:`EstimatorSpec.config`); default the
            class's defaults.
        num: build the batched form of ``num`` estimators (the vector environment).
        schedule: the true efficiency schedule ``t -> (n,)``, given to the oracle only.
        options: ``quadfault estimate`` options instead of ``config``
            (:func:`config_from_options`).
    """
    if not isinstance(name, str):
        if (
            num is None
            and callable(getattr(name, "update", None))
            and callable(getattr(name, "reset", None))
        ):
            return name
        raise ConfigError(
            f"estimator must be one of {', '.join(ESTIMATORS)} or an object with "
            f"reset() and update(sample), got {name!r}"
        )
    spec = estimator_spec(name)
    if options:
        from_options = config_from_options(name, **options)
        if from_options is not None:
            if config is not None:
                raise ConfigError(f"estimator {name!r}: give config or options, not both")
            config = from_options
    if config is not None and spec.config is None:
        raise ConfigError(f"estimator {name!r} takes no configuration, got {config!r}")
    kwargs = {} if config is None else {"config": config}
    if num is not None:
        return estimator_class(name, batched=True)(vehicle, num, **kwargs)
    if spec.role == "oracle":
        kwargs["schedule"] = schedule
    return estimator_class(name)(vehicle, **kwargs)


__all__ = [
    "ESTIMATORS",
    "OPTIONS",
    "ROLES",
    "TABLE",
    "EstimatorSpec",
    "config_class",
    "config_from_options",
    "estimator_class",
    "estimator_names",
    "estimator_spec",
    "make_estimator",
]
