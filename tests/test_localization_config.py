"""The localiser's configuration: nav2's defaults, loud refusal of bad keys and values."""

import dataclasses
import math

import pytest

from localization import LocalizationError, LocalizerConfig


def test_defaults_are_nav2_amcl_where_not_documented_otherwise():
    c = LocalizerConfig()
    assert c.alphas == (0.2, 0.2, 0.2, 0.2)
    assert (c.laser_likelihood_max_dist, c.z_hit, c.z_rand, c.sigma_hit, c.max_beams) == \
        (2.0, 0.5, 0.5, 0.2, 60)
    assert (c.min_particles, c.max_particles, c.pf_err, c.pf_z) == (500, 2000, 0.05, 0.99)
    assert (c.update_min_d, c.update_min_a, c.resample_interval) == (0.25, 0.2, 1)
    assert (c.recovery_alpha_slow, c.recovery_alpha_fast) == (0.0, 0.0)
    assert not c.recovery_enabled
    assert (c.kld_bin_xy, c.kld_bin_theta) == (0.5, pytest.approx(math.radians(10)))
    # The documented departures (localization/README.md):
    assert (c.laser_model_type, c.importance_factor, c.min_ess_fraction) == \
        ("likelihood_field_prob", 1.0, 0.02)


def test_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        LocalizerConfig().alpha1 = 0.1


def test_from_dict_accepts_ints_for_floats():
    c = LocalizerConfig.from_dict({"laser_likelihood_max_dist": 3, "max_particles": 5000,
                                   "recovery_alpha_slow": 0.001, "recovery_alpha_fast": 0.1})
    assert c.laser_likelihood_max_dist == 3.0 and isinstance(c.laser_likelihood_max_dist, float)
    assert c.max_particles == 5000 and c.recovery_enabled


def test_unknown_key_is_refused_with_the_nearest_name():
    with pytest.raises(LocalizationError, match=r"unknown key 'max_particle'.*'max_particles'"):
        LocalizerConfig.from_dict({"max_particle": 10})
    with pytest.raises(LocalizationError, match=r"unknown key 'zzz'$"):
        LocalizerConfig.from_dict({"zzz": 1})


@pytest.mark.parametrize("key,value", [
    ("alpha1", -0.1), ("sigma_hit", 0.0), ("max_beams", 1), ("max_beams", 2.5),
    ("min_particles", 0), ("pf_err", float("nan")), ("resample_interval", True),
    ("recovery_alpha_fast", 1.5), ("laser_model_type", "beam"), ("resampler", "best"),
    ("z_hit", "0.5"), ("min_ess_fraction", 2.0)])
def test_bad_values_are_refused_naming_the_key(key, value):
    with pytest.raises(LocalizationError, match=key):
        LocalizerConfig.from_dict({key: value})


def test_min_above_max_particles():
    with pytest.raises(LocalizationError, match="min_particles"):
        LocalizerConfig(min_particles=3000)


def test_from_yaml(tmp_path):
    path = tmp_path / "amcl.yaml"
    path.write_text("localization:\n  alpha1: 0.05\n  laser_model_type: likelihood_field\n")
    c = LocalizerConfig.from_yaml(path)
    assert c.alpha1 == 0.05 and c.laser_model_type == "likelihood_field"
    path.write_text("alpha2: 0.1\nmax_beam: 30\n")
    with pytest.raises(LocalizationError, match=r"amcl.yaml: unknown key 'max_beam'"):
        LocalizerConfig.from_yaml(path)
    with pytest.raises(LocalizationError, match="cannot read"):
        LocalizerConfig.from_yaml(tmp_path / "missing.yaml")


def test_from_yaml_takes_the_robot_files_section_name_too(tmp_path):
    path = tmp_path / "loc.yaml"
    path.write_text("localizer:\n  max_particles: 900\n")
    assert LocalizerConfig.from_yaml(path) == LocalizerConfig(max_particles=900)
