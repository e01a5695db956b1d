"""The estimators' settings reader (estimators/options.py): one set of checks and one reader
of ``quadfault estimate``'s options for the EKF, UKF and RLS configurations."""

import math

import pytest

from estimators.ekf import EKFConfig
from estimators.options import from_options
from estimators.rls import RLSConfig
from estimators.ukf import UKFConfig
from quadfault.errors import ConfigError


@pytest.mark.parametrize(
    "cls, key",
    [(EKFConfig, "q_eta"), (EKFConfig, "r_attitude"), (UKFConfig, "alpha"), (RLSConfig, "p0")],
)
@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf, True, "0.1", None])
def test_a_setting_that_is_not_a_positive_number_is_a_one_line_error(cls, key, bad):
    with pytest.raises(ConfigError, match=rf"^{cls.__name__}\.{key} must be a positive number"):
        cls(**{key: bad})


@pytest.mark.parametrize("cls", [EKFConfig, UKFConfig, RLSConfig])
@pytest.mark.parametrize("bounds", [(1.0,), (1.0, 0.5), (0.0, 0.0), ("a", "b"), 3.0])
def test_bad_efficiency_bounds_are_a_one_line_error(cls, bounds):
    with pytest.raises(ConfigError, match=rf"^{cls.__name__}\.eta_bounds must be \(low, high\)"):
        cls(eta_bounds=bounds)


def test_the_other_ranges():
    with pytest.raises(ConfigError, match=r"^UKFConfig\.kappa must be a finite number"):
        UKFConfig(kappa=math.nan)
    with pytest.raises(ConfigError, match=r"^RLSConfig\.forgetting must be in \(0, 1\]"):
        RLSConfig(forgetting=1.5)
    with pytest.raises(ConfigError, match=r"^RLSConfig\.prefilter must be a time constant"):
        RLSConfig(prefilter=-0.01)


def test_options_replace_the_defaults_and_none_keeps_them():
    assert EKFConfig.from_options() == EKFConfig()
    assert EKFConfig.from_options(q_eta=2) == EKFConfig(q_eta=2.0)
    assert isinstance(EKFConfig.from_options(q_eta=2).q_eta, float)
    assert UKFConfig.from_options(q_eta=0.25) == UKFConfig(q_eta=0.25)
    rls = RLSConfig.from_options(forgetting=0.95)
    assert (rls.forgetting, rls.prefilter) == (0.95, RLSConfig().prefilter)
    assert from_options(RLSConfig, prefilter=None, forgetting=None) == RLSConfig()
    with pytest.raises(ConfigError, match=r"^EKFConfig\.q_eta must be a positive number"):
        EKFConfig.from_options(q_eta="fast")
