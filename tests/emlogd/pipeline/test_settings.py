"""The pipeline's settings: the filter's tuning they derive, the reference noise by field."""

from __future__ import annotations

import dataclasses

import pytest

from emlogd.pipeline.settings import REF_NOISE_MPS, PortSettings, UutSettings


def test_settings_built_in_code_tune_the_filter() -> None:
    """UutSettings made directly (the offline commands) give the filter their noises."""
    s = UutSettings(port="a", reference_port="b", r_raw_mps=0.1, q_params=1e-6)
    assert s.kf.r_raw_mps2 == pytest.approx(0.01) and s.kf.q_params == 1e-6
    assert dataclasses.replace(s, p0=0.5).kf.p0 == 0.5


@pytest.mark.parametrize("field", sorted(REF_NOISE_MPS))
def test_the_reference_noise_follows_the_reference_field(field: str) -> None:
    """Without r_ref_mps the filter takes the noise of the reference's kind; with it, it."""
    s = UutSettings(port="a", reference_port="b", reference_field=field)  # type: ignore[arg-type]
    assert s.kf.r_ref_mps2 == pytest.approx(REF_NOISE_MPS[field] ** 2)
    assert dataclasses.replace(s, r_ref_mps=0.2).kf.r_ref_mps2 == pytest.approx(0.04)


def test_a_port_is_stale_after_five_silent_seconds_by_default() -> None:
    """A port's settings default to the NMEA checksum required, 82 characters, 5 s."""
    p = PortSettings("dvl", "pd6")
    assert (p.checksum, p.max_length, p.stale_timeout_s) == ("required", 82, 5.0)
