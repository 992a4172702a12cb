"""The calibration file: one format for the daemon's state file and ``calibrate --save``.

YAML, under a kind and a schema version, one entry per UUT, each a
:class:`~emlogd.pipeline.calibration.Calibration`::

    kind: emlogd-calibration
    schema: 2
    saved_at: '2026-11-24T10:00:00+00:00'
    uuts:
      emlog1:
        model: EM3            # EM1 … EM4
        method: online        # online (the daemon), kf or ls (emlogd calibrate)
        reset: false          # true: the operator reset it; no calibration
        params: {m: 0.0512, b: 0.1031}
        param_std: {m: 0.0021, b: 0.0034}   # null: not determined by the data
        lag_s: 3.21
        current: true         # estimated with the current states
        current_mps: {north: -0.09, east: -0.07}          # null: not determined
        current_std_mps: {north: 0.004, east: 0.004}
        covariance: [[...], ...]   # the filter's, over [v, θ…, c_N, c_E]; [] for ls
        t: 1749715200.0       # record time the calibration refers to, s
        n_samples: 12034
        reference: {port: dvl, field: bottom}
        unidentifiable: []
        nis_mean: 1.01
        two_axis: {misalign_deg: 3.1, misalign_std_deg: 0.14, m_t: -0.08, m_t_std: 0.005,
                   b_t_mps: 0.04, b_t_std_mps: 0.004,   # axes: 2 only: the validated figures,
                   lon_a_spm: 0.0, lon_m: -0.11, lon_b_mps: -0.05}  # with the fit's forward
                                      # axis when it determined it (all three or none)
        extra: {}             # producer's notes (offline: captures, RMSE)
    others:                   # the daemon's state only: each UUT's other error models
      emlog1:
        EM4: {...}            # an entry as above, kept for a switch back to EM4
    end: true                 # last key: a truncated file is detected

Parsing is strict (:class:`CalibrationFileError` names the key); whether a record may
be *used* is :func:`emlogd.pipeline.calibration.check`, applied by whoever loads it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from datetime import UTC, datetime
from typing import Any

import yaml

from calib.errors import CalibrationError
from calib.estimate import Estimate
from calib.models import MODEL_NAMES, PARAM_NAMES, Params
from drivers.errors import EmlogdError
from emlogd.configyaml import YAML_FAILURES, yaml_depth_error
from emlogd.pipeline.calibration import TWO_AXIS_KEYS, TWO_AXIS_LON_KEYS, Calibration

KIND = "emlogd-calibration"
SCHEMA = 2


class CalibrationFileError(EmlogdError):
    """A calibration file is damaged, of another kind or of another schema."""


def _f(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _ne(pair: tuple[float, float] | None) -> dict[str, float | None] | None:
    return None if pair is None else {"north": _f(pair[0]), "east": _f(pair[1])}


def to_dict(cal: Calibration, extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """One entry as plain types (``two_axis`` only when the record has the figures)."""
    two = {} if cal.two_axis is None else {"two_axis": {k: _f(v) for k, v in cal.two_axis.items()}}
    return {
        "model": cal.params.model,
        "method": cal.method,
        "reset": cal.reset,
        "params": {k: _f(v) for k, v in cal.params.as_dict().items()},
        "param_std": {k: _f(v) for k, v in cal.param_std.items()},
        "lag_s": _f(cal.lag_s),
        "current": cal.current,
        "current_mps": _ne(cal.current_mps),
        "current_std_mps": _ne(cal.current_std_mps),
        "covariance": [[_f(x) for x in row] for row in cal.covariance],
        "t": float(cal.t),
        "n_samples": int(cal.n_samples),
        "reference": dict(cal.reference),
        "unidentifiable": list(cal.unidentifiable),
        "nis_mean": _f(cal.nis_mean),
        **two,
        "extra": dict(extra or {}),
    }


def dumps(
    cals: Mapping[str, Calibration],
    extra: Mapping[str, Mapping[str, Any]] | None = None,
    others: Iterable[Calibration] = (),
) -> str:
    """The file's text (the end marker comes last, so a truncated file is detected).

    ``others``: calibrations of the UUTs' other error models (the daemon's state), under
    ``others`` by UUT and model; the section is left out when there are none.
    """
    doc: dict[str, Any] = {
        "kind": KIND,
        "schema": SCHEMA,
        "saved_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "uuts": {uut: to_dict(c, (extra or {}).get(uut)) for uut, c in cals.items()},
    }
    by_uut: dict[str, dict[str, Any]] = {}
    for c in others:
        by_uut.setdefault(c.uut, {})[c.params.model] = to_dict(c)
    if by_uut:
        doc["others"] = by_uut
    doc["end"] = True
    return "# emlogd calibration (do not edit while the daemon runs)\n" + yaml.safe_dump(
        doc, sort_keys=False
    )


def _num(v: Any, where: str, *, allow_none: bool = False) -> float | None:
    if v is None and allow_none:
        return None
    return _req(v, where)


def _req(v: Any, where: str) -> float:
    x = _finite(v)
    if x is None:
        shown = repr(v) if not isinstance(v, int) or abs(v) < 10**20 else "a huge integer"
        raise CalibrationFileError(f"{where}: expected a finite number, got {shown}")
    return x


def _finite(v: Any) -> float | None:
    """``v`` as a finite float, or None (not a number, a bool, inf, nan, or an integer
    too large for a float)."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return None
    try:
        x = float(v)
    except OverflowError:
        return None
    return x if math.isfinite(x) else None


def _pair(v: Any, where: str) -> tuple[float, float] | None:
    if v is None:
        return None
    if not isinstance(v, dict):
        raise CalibrationFileError(f"{where}: expected {{north, east}}")
    return (_req(v.get("north"), f"{where}.north"), _req(v.get("east"), f"{where}.east"))


def _covariance(v: Any, where: str) -> tuple[tuple[float, ...], ...]:
    """A square matrix of finite numbers (``[]``: none)."""
    if not isinstance(v, list) or not all(isinstance(r, list) for r in v):
        raise CalibrationFileError(f"{where}: expected a list of rows")
    if any(len(row) != len(v) for row in v):
        raise CalibrationFileError(f"{where}: expected a square matrix")
    return tuple(tuple(_req(x, where) for x in row) for row in v)


def from_dict(uut: str, d: Any) -> tuple[Calibration, dict[str, Any]]:
    """One entry from plain types; returns the record and its ``extra`` notes.

    Raises:
        CalibrationFileError: anything malformed (the message names the key).
    """
    w = f"uuts.{uut}"
    if not isinstance(d, dict):
        raise CalibrationFileError(f"{w}: expected a mapping")
    model = d.get("model")
    if model not in MODEL_NAMES:
        raise CalibrationFileError(f"{w}.model: {model!r} is not one of {', '.join(MODEL_NAMES)}")
    names = PARAM_NAMES[model]
    values = d.get("params")
    if not isinstance(values, dict) or set(values) != set(names):
        raise CalibrationFileError(f"{w}.params: {model} has {', '.join(names)}")
    try:
        params = Params.from_theta(model, [_req(values[n], f"{w}.params.{n}") for n in names])
    except CalibrationError as exc:
        raise CalibrationFileError(f"{w}.params: {exc}") from None
    std_raw = d.get("param_std") or {}
    if not isinstance(std_raw, dict) or not set(std_raw) <= set(names):
        raise CalibrationFileError(f"{w}.param_std: keys must be among {', '.join(names)}")
    std = {str(k): _num(v, f"{w}.param_std.{k}", allow_none=True) for k, v in std_raw.items()}
    method = d.get("method", "online")
    if method not in ("online", "kf", "ls"):
        raise CalibrationFileError(f"{w}.method: {method!r} is not online, kf or ls")
    cov = _covariance(d.get("covariance") or [], f"{w}.covariance")
    n = d.get("n_samples", 0)
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise CalibrationFileError(f"{w}.n_samples: expected a count, got {n!r}")
    ref = d.get("reference") or {}
    if not isinstance(ref, dict):
        raise CalibrationFileError(f"{w}.reference: expected a mapping")
    unid = d.get("unidentifiable") or []
    if not isinstance(unid, list) or not all(isinstance(x, str) for x in unid):
        raise CalibrationFileError(f"{w}.unidentifiable: expected a list of names")
    extra = d.get("extra") or {}
    if not isinstance(extra, dict):
        raise CalibrationFileError(f"{w}.extra: expected a mapping")
    lag_s = _num(d.get("lag_s"), f"{w}.lag_s", allow_none=True)
    current_mps = _pair(d.get("current_mps"), f"{w}.current_mps")
    current_std_mps = _pair(d.get("current_std_mps"), f"{w}.current_std_mps")
    cal = Calibration(
        uut=uut,
        estimate=Estimate(params, std, current_mps, current_std_mps),
        lag_s=lag_s,
        current=bool(d.get("current", False)),
        covariance=cov,
        method=method,
        t=_req(d.get("t", 0.0), f"{w}.t"),
        n_samples=n,
        reference={str(k): str(v) for k, v in ref.items()},
        unidentifiable=tuple(unid),
        nis_mean=_num(d.get("nis_mean"), f"{w}.nis_mean", allow_none=True),
        reset=bool(d.get("reset", False)),
        two_axis=_two_axis(d.get("two_axis"), f"{w}.two_axis"),
    )
    return cal, extra


def _two_axis(v: Any, where: str) -> dict[str, float] | None:
    """A record's two-axis figures: finite numbers by name (their bounds are
    :func:`emlogd.pipeline.calibration.check`'s)."""
    if v is None:
        return None
    lon = TWO_AXIS_LON_KEYS if isinstance(v, dict) and "lon_m" in v else ()
    if not isinstance(v, dict) or set(v) != set(TWO_AXIS_KEYS + lon):
        raise CalibrationFileError(
            f"{where}: expected {', '.join(TWO_AXIS_KEYS)} "
            f"(and {', '.join(TWO_AXIS_LON_KEYS)}, all or none)"
        )
    return {k: _req(v[k], f"{where}.{k}") for k in TWO_AXIS_KEYS + lon}


def loads(text: str) -> tuple[dict[str, Calibration], dict[str, dict[str, Any]]]:
    """Parse a file's text: the records by UUT and their ``extra`` notes.

    Raises:
        CalibrationFileError: not YAML, wrong kind or schema, truncated, malformed.
    """
    cals, extras, _ = _parse(text)
    return cals, extras


def loads_state(text: str) -> tuple[dict[str, Calibration], list[Calibration]]:
    """Parse a state file's text: the records in use by UUT, and the UUTs' records of
    their other error models (``others``).

    Raises:
        CalibrationFileError: as :func:`loads`; also an ``others`` entry whose model is
            not the one it is filed under.
    """
    cals, _, others = _parse(text)
    return cals, others


def _load_yaml(text: str) -> Any:
    """The YAML document of ``text``, whatever the loader raised made a
    :class:`CalibrationFileError` (nesting past :data:`emlogd.configyaml.MAX_YAML_DEPTH`
    refused unparsed)."""
    deep = yaml_depth_error(text)
    if deep:
        raise CalibrationFileError(f"not valid YAML ({deep})")
    try:
        return yaml.safe_load(text)
    except YAML_FAILURES as exc:
        raise CalibrationFileError(f"not valid YAML ({exc.__class__.__name__})") from None


def _parse(
    text: str,
) -> tuple[dict[str, Calibration], dict[str, dict[str, Any]], list[Calibration]]:
    doc = _load_yaml(text)
    if not isinstance(doc, dict) or doc.get("kind") != KIND:
        raise CalibrationFileError("not an emlogd calibration file")
    if doc.get("schema") != SCHEMA:
        raise CalibrationFileError(f"schema {doc.get('schema')!r}, this emlogd reads {SCHEMA}")
    uuts = doc.get("uuts")
    if not isinstance(uuts, dict):
        raise CalibrationFileError("missing uuts")
    if doc.get("end") is not True:
        raise CalibrationFileError("truncated (no end marker)")
    cals: dict[str, Calibration] = {}
    extras: dict[str, dict[str, Any]] = {}
    for k, v in uuts.items():
        cals[str(k)], extras[str(k)] = from_dict(str(k), v)
    others: list[Calibration] = []
    kept = doc.get("others") or {}
    if not isinstance(kept, dict):
        raise CalibrationFileError("others: expected a mapping of UUTs")
    for uut, models in kept.items():
        if not isinstance(models, dict):
            raise CalibrationFileError(f"others.{uut}: expected a mapping of models")
        for model, entry in models.items():
            cal, _ = from_dict(str(uut), entry)
            if cal.params.model != model:
                raise CalibrationFileError(
                    f"others.{uut}.{model}: holds a {cal.params.model} calibration"
                )
            others.append(cal)
    return cals, extras, others
