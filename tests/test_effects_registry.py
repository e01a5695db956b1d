"""The effect registry: one table, every effect's declarations readable from it."""

import pytest

from quadfault.effects import registry
from quadfault.effects.base import CHANNELS, Identifiability
from quadfault.errors import ConfigError


def test_every_effect_is_registered_once_with_a_unique_name():
    names = registry.names()
    assert len(set(names)) == len(names) == len(registry.TABLE)
    for k, name in enumerate(names):
        assert registry.code(name) == k
        assert registry.effect_class(name).name == name


@pytest.mark.parametrize("name", registry.names())
def test_every_effect_declares_what_a_recording_needs(name):
    need = registry.identifiability(name)
    assert isinstance(need, Identifiability)
    assert set(need.channels + need.any_of + need.direct) <= set(CHANNELS)
    assert need.note  # a reason a user can read
    if need.timescale is not None:  # a reported parameter of the effect
        assert need.timescale in registry.effect_class(name)().params()


def test_declarations_follow_the_physics():
    """Forces against the velocity need it; a lag needs fast commands and rotor speeds show
    it directly; the battery effect needs the voltage."""
    for name in ("drag", "wind", "blade_flapping"):
        assert "velocity" in registry.identifiability(name).channels
    lag = registry.identifiability("motor_lag")
    assert lag.min_command_rate > 10.0 and "rotor_speed" in lag.direct
    assert registry.identifiability("battery_thrust").columns() == ("vbat",)


def test_unknown_names_are_one_line_errors():
    with pytest.raises(ConfigError, match="unknown effect 'lag'"):
        registry.identifiability("lag")
    with pytest.raises(ValueError, match="unknown channel group"):
        Identifiability(channels=("speed",))
