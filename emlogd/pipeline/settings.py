"""The pipeline's settings: what one input port and one calibrated UUT are configured with.

The dataclasses' fields made with :func:`~emlogd.pipeline.keys.key` are the config's
keys (the loaded config holds these objects as they are, :mod:`emlogd.config`); the
pipeline's modules read them and nothing here imports those modules, so the imports
inside ``emlogd/pipeline`` go one way (tests/test_layering.py checks there is no cycle).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

from calib.excitation import ExcitationRule
from calib.kalman import DEFAULT_R_RAW_MPS2, DEFAULT_R_REF_MPS2, KfConfig
from calib.models import MODEL_NAMES, PARAM_NAMES, check_model
from drivers import protocol_names
from drivers.base import LINE_BUFFER_CAP, NMEA_MAX_LENGTH, SHORTEST_LINE_LIMIT
from emlogd.pipeline.integrity import Envelope
from emlogd.pipeline.keys import (
    NAME,
    bool_or_auto,
    boolean,
    enum,
    group,
    key,
    lag,
    literal,
    number,
    or_null,
    param_std,
    port_or_auto,
    string,
)
from emlogd.pipeline.readings import ReadingLimits

RefField = Literal["bottom", "water", "speed", "gnss"]
"""A UUT's reference: the speed records of that role (:data:`drivers.records.SpeedRole`)
on its reference port, or ``gnss``: the GNSS speed and course projected on the hull."""
Checksum = Literal["required", "optional"]
Component = Literal["longitudinal", "magnitude"]
HeadingSource = str
"""``auto`` or a port name."""

UutSentence = Literal["VHW", "VBW"]
"""The NMEA sentences an EMlog's reading is calibrated and corrected in."""


REF_NOISE_MPS: dict[str, float] = {
    "bottom": math.sqrt(DEFAULT_R_REF_MPS2),
    "water": math.sqrt(DEFAULT_R_REF_MPS2),
    "speed": math.sqrt(DEFAULT_R_RAW_MPS2),
    "gnss": 0.3,
}
"""Default 1σ noise of each kind of reference, m/s. A DVL's bottom or water track:
0.01. Another EMlog: its own reading noise. GNSS: speed over ground projected on the
hull is 1 Hz, filtered by the receiver, and projected with a heading a few degrees
off and a course that wanders at low speed; 0.3 m/s is what the along-hull residual
of real yacht logs shows (docs/REAL_DATA.md)."""


_KF = KfConfig()


@dataclass(frozen=True, slots=True)
class PortSettings:
    """What the pipeline needs to know about one input port (the ``ports`` keys that
    are the pipeline's; the device's are :class:`emlogd.config.PortConfig`'s)."""

    name: str = key(
        check=string(NAME, "a port name (letters, digits, _ . -; at most 32)"),
        doc="The port's name, used by `calibration` and in the logs.",
    )
    protocol: str = key(
        check=enum(*sorted(protocol_names())),
        doc="What the device speaks.",
    )
    checksum: Checksum = key(
        "required",
        check=literal(Checksum),
        doc="optional: NMEA sentences without `*hh` are accepted (a wrong one never is).",
    )
    max_length: int = key(
        NMEA_MAX_LENGTH,
        check=number(SHORTEST_LINE_LIMIT, LINE_BUFFER_CAP, integer=True),
        unit="characters",
        doc="The longest line accepted; raise for devices that send longer lines.",
    )
    stale_timeout_s: float = key(
        5.0,
        check=number(0.0, 3600.0, lo_open=True),
        unit="s",
        doc="Silent this long, the port is stale (a stale reference is not learnt from).",
    )


@dataclass(frozen=True, slots=True)
class UutSettings:
    """Calibration of one UUT (the ``calibration`` section of the config).

    ``misalign_deg``, ``transverse_scale`` and ``transverse_bias_mps`` are a two-axis
    log's frozen installation figures (:class:`calib.twoaxis.TwoAxisParams`, learnt
    offline by ``emlogd calibrate --axes 2``), applied to its VBW
    (:mod:`emlogd.pipeline.twoaxis`).

    The fields made with :func:`~emlogd.pipeline.keys.key` are the ``calibration``
    keys; the others the config loader fills from elsewhere (the reference port's
    ``stale_timeout_s``, the ``outputs`` section).
    """

    port: str = key(name="uut", check=string(NAME, "a port name"), doc="The EMlog's port.")
    reference_port: str = key(
        name="reference",
        check=string(NAME, "a port name"),
        doc="The reference's port: a DVL, another EMlog, or a GNSS receiver.",
    )
    model: str = key(
        "EM3",
        check=enum(*MODEL_NAMES),
        doc="The error model: EM1 (b), EM2 (m), EM3 (m, b), EM4 (a, m, b).",
    )
    reference_field: RefField = key(
        "bottom",
        check=literal(RefField),
        doc="bottom (DVL bottom track), water (DVL `:WS`), speed (another EMlog), gnss "
        "(RMC/VTG speed and course, projected on the hull).",
    )
    uut_source: UutSentence = key(
        "VHW", check=literal(UutSentence), doc="The EMlog sentence calibrated and corrected."
    )
    talker: str = key(
        "VW",
        check=or_null(string(r"[A-Z]{2}", "two uppercase letters")),
        absent=None,
        doc="The talker of this log's corrected sentences; null: `outputs.talker`.",
    )
    misalign_deg: float = key(
        0.0,
        check=number(-20.0, 20.0),
        unit="°",
        doc="VBW: the log's forward axis from the bow (+ to starboard), from `emlogd "
        "calibrate --axes 2`; the corrected VBW turns both axes back by it.",
    )
    transverse_scale: float = key(
        0.0,
        check=number(-0.5, 0.5),
        doc="VBW: the athwart axis's scale error m_t (`calibrate --axes 2`): the corrected "
        "athwart speed is (reading − `transverse_bias_mps`)/(1 + m_t).",
    )
    transverse_bias_mps: float = key(
        0.0,
        check=number(-1.0, 1.0),
        unit="m/s",
        doc="VBW: the athwart axis's bias (`calibrate --axes 2`).",
    )
    axes: int = key(
        1,
        check=number(1, 2, integer=True),
        doc="2: learn the VBW's misalignment, transverse scale and bias online against a "
        "two-axis reference (a DVL's bottom track) and apply them to the corrected VBW once "
        "its athwart speed beats the raw one (`emlogd.pipeline.twoaxis_learn`), and the "
        "fit's forward axis to the VBW's and VHW's forward speed once that beats the "
        "one-axis calibration's; 1: the longitudinal axis only.",
    )
    component: Component = key(
        "longitudinal",
        check=literal(Component),
        doc="magnitude: the horizontal speed of both (EMlogs that measure it).",
    )
    current: bool = key(
        False,
        check=bool_or_auto,
        absent="auto",
        doc="Estimate the sea current (north, east) too: the water frame. auto: wherever a "
        "heading is known to come (a DVL that sends one, GNSS, or a heading port named); "
        "false: the calibration against the ground speed.",
    )
    heading: HeadingSource = key(
        "auto",
        check=port_or_auto(),
        doc="The heading's port; auto: the reference's heading, else the UUT's VHW, else any "
        "port with HDT/HDG.",
    )
    magnetic_variation_deg: float | None = key(
        None,
        check=number(-180.0, 180.0, optional=True),
        unit="°",
        doc="East positive; for magnetic headings when no HDG/RMC carries one (without it: "
        "the IGRF model at the GNSS position).",
    )
    lag_s: float | None = key(
        None,
        name="lag",
        check=lag,
        unit="s",
        show=lambda v: "auto" if v is None else v,
        doc="The EMlog's lag behind the reference; auto: estimated by cross-correlation "
        "from the first `lag_window_s` on, used once accepted (never negative, σ ≤ 0.1 s), "
        "then fixed; until then 0 s, said in the status reason. Either is checked every "
        "5 min of readings over ±180 s: a lag the data contradict (auto: a best lag 30 s "
        "or more away, found twice) stops learning and applying, said in the status.",
    )
    lag_window_s: float = key(
        300.0,
        check=number(10.0, 7200.0),
        unit="s",
        doc="Data collected before the lag is estimated.",
    )
    max_lag_s: float = key(
        10.0,
        check=number(0.0, 30.0, lo_open=True),
        unit="s",
        doc="The longest lag: the reference is buffered this far back.",
    )
    learn: bool = key(True, check=boolean, doc="Learn at start (the control socket may switch it).")
    apply: bool = key(
        True, check=boolean, doc="false: the status sentence only, no corrected speed."
    )
    min_ref_speed_mps: float = key(
        0.3, check=number(0.0, 20.0), unit="m/s", doc="No learning below this reference speed."
    )
    min_sog_mps: float = key(
        0.5,
        check=number(0.0, 20.0),
        unit="m/s",
        doc="gnss: below this speed over ground the course is meaningless, no learning.",
    )
    ref_stale_s: float = 5.0
    max_param_std: Mapping[str, float] = key(
        factory=lambda: {"a": 0.02, "m": 0.05, "b": 0.08},
        check=param_std(PARAM_NAMES["EM4"], 0.0, 10.0),
        doc="A calibration is a candidate once its parameters' σ are below these.",
    )
    excitation_half_life_samples: float = key(
        600.0,
        check=number(1.0, 86400.0),
        unit="samples",
        doc="Half-life of the excitation rule's memory of recent speeds.",
    )
    r_raw_mps: float = key(
        math.sqrt(_KF.r_raw_mps2),
        check=number(0.0, 10.0, lo_open=True),
        unit="m/s",
        doc="The EMlog's 1σ noise (0.1 kn, the DX900+ specification).",
    )
    r_ref_mps: float | None = key(
        None,
        check=number(0.0, 10.0, lo_open=True, optional=True),
        unit="m/s",
        doc="The reference's 1σ noise; null: by reference field (0.01 for a DVL or its water "
        "track, the EMlog's own for another log, 0.3 for GNSS).",
    )
    q_params: float = key(
        _KF.q_params,
        check=number(0.0, 1.0),
        doc="Random walk of the parameters per second, at most per sample, in the water "
        "frame (the paper's Q per step of its 1-Hz log); against the ground, per sample.",
    )
    p0: float = key(
        _KF.p0, check=number(0.0, 100.0, lo_open=True), doc="Initial variance (the paper's P0)."
    )
    current_psd_m2ps3: float = key(
        _KF.current_psd_m2ps3,
        check=number(0.0, 1.0),
        unit="m²/s³",
        doc="How fast the current may change (random walk).",
    )
    persist_interval_s: float = key(
        60.0,
        check=number(0.0, 86400.0),
        unit="s",
        doc="The calibration in use is persisted at most this often.",
    )
    persist_min_change_sigma: float = key(
        1.0,
        check=number(0.0, 100.0),
        unit="σ",
        doc="A change smaller than this many σ is not persisted.",
    )
    persist_min_change_abs: float = key(
        1e-3,
        check=number(0.0, 10.0),
        doc="Nor is a change smaller than this in every parameter.",
    )
    rule: ExcitationRule = field(default_factory=ExcitationRule)
    maker: str = "EML"
    status_sentence_interval_s: float = 1.0
    gate_nis: float = key(
        25.0,
        check=number(1.0, 1e6),
        doc="A sample whose innovation is beyond this NIS is not learnt.",
    )
    relearn_gates: int = key(
        30,
        check=number(1, 100_000, integer=True),
        doc="This many gated samples in a row: the filter restarts from the last good state.",
    )
    envelope: Envelope = group(Envelope)
    limits: ReadingLimits = group(ReadingLimits)
    low_speed_mps: float = key(
        0.25,
        check=number(0.0, 5.0),
        unit="m/s",
        doc="Below this the correction fades to the raw reading.",
    )
    stuck_s: float = key(
        60.0,
        check=number(1.0, 86400.0),
        unit="s",
        doc="A reading that does not change this long while the reference moves: stuck.",
    )
    zero_s: float = key(
        10.0,
        check=number(1.0, 86400.0),
        unit="s",
        doc="A zero reading this long while the reference moves: a fault.",
    )
    max_accel_mps2: float = key(
        2.0,
        check=number(0.0, 100.0, lo_open=True),
        unit="m/s²",
        doc="A reference jump needing more than this is a glitch.",
    )
    max_turn_rate_dps: float = key(
        45.0,
        check=number(0.0, 360.0, lo_open=True),
        unit="°/s",
        doc="A heading jump needing more than this is a glitch.",
    )
    validation_s: float = key(
        120.0,
        check=number(0.1, 3600.0),
        unit="s",
        doc="A new calibration must beat the one in use this long before it is applied.",
    )
    average_s: float | None = key(
        None,
        check=number(0.0, 600.0, optional=True),
        unit="s",
        doc="Learn from block means this long; null: 20 s for gnss, else every sample; 0: "
        "every sample (a noisy reference's errors are correlated).",
    )
    recheck_s: float = key(
        300.0,
        check=number(1.0, 86400.0),
        unit="s",
        doc="The calibration in use is checked against the raw reading this often.",
    )
    _kf: KfConfig = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        check_model(self.model)
        r_ref = (
            self.r_ref_mps if self.r_ref_mps is not None else REF_NOISE_MPS[self.reference_field]
        )
        object.__setattr__(
            self,
            "_kf",
            dataclasses.replace(
                _KF,
                r_raw_mps2=self.r_raw_mps**2,
                r_ref_mps2=r_ref**2,
                q_params=self.q_params,
                p0=self.p0,
                current_psd_m2ps3=self.current_psd_m2ps3,
            ),
        )

    @property
    def kf(self) -> KfConfig:
        """The filter's tuning: :class:`KfConfig`'s defaults with the noises, ``q_params``,
        ``p0`` and ``current_psd_m2ps3`` of these settings."""
        return self._kf
