"""A GNSS receiver and a heading as the two-axis reference of ``--axes 2``.

Each fix's ground velocity (RMC or VTG: speed and course over ground, true) is
turned into the hull frame by the heading at the fix,

    g_f =  v_N·cos ψ + v_E·sin ψ        (forward)
    g_s = −v_N·sin ψ + v_E·cos ψ        (to starboard)

and the current stays a water-frame unknown shared by both axes, as against a DVL's
bottom track (:mod:`emlogd.offline.twoaxis`). The heading is a true one: HDT, a
DVL's, VHW's true heading, or a magnetic one (HDG, HDM, VHW's magnetic) turned by
its own variation (HDG's) or the one given. Without any, the capture is refused
with the reason: the velocity over ground cannot be split into the hull's axes.

The commands do not take it as a reference yet (``--axes 2`` needs ``--ref-field
bottom``): a receiver's 0.05 m/s of noise per axis is noise in the regressor, which
least squares takes as signal and so pulls each scale toward −1 (errors in
variables). On the simulated figure-8 of 2026-11-27 (``emlogd simulate --seed 1
--sensor emlog2:misalign=3,mt=-0.08,bt=0.04``, the DVL's heading, ``age_s`` 0.77,
lag −0.32 s) :func:`calib.twoaxis.fit_two_axis` gave the transverse scale −0.21 for
−0.08 and α a σ of 0.18° (0.82° once the residuals' correlation, one fix per ten
readings, is counted). A DVL's 0.01 m/s leaves 4 % of that.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from drivers import make_decoder
from drivers.io.capture import CaptureReader
from drivers.nmea0183.records import Heading, Rmc, Vtg
from drivers.records import Rejected, SpeedRecord
from emlogd.offline.jobs import OfflineError
from emlogd.offline.twoaxis import TwoAxisRecording
from emlogd.pipeline.align import DEFAULT_MAX_GAP_S, interpolate


@dataclass
class _Collect:
    """What one capture gives: the log's VBW pairs, the fixes and the headings."""

    uut: str
    gnss: str
    heading: str | None
    variation_deg: float | None
    read: list[tuple[float, float, float]] = field(default_factory=list)
    fixes: list[tuple[float, float, float]] = field(default_factory=list)
    hdg: list[tuple[float, float]] = field(default_factory=list)
    magnetic: int = 0
    """Magnetic headings left out: no variation."""

    def heads(self, port: str) -> bool:
        """Whether a port's headings are taken."""
        return port != self.uut and port != self.gnss and self.heading in (None, port)

    def take(self, t: float, port: str, rec: object, speeds: tuple[SpeedRecord, ...]) -> None:
        if port == self.gnss and isinstance(rec, (Rmc, Vtg)):
            if rec.valid and rec.sog_mps is not None and rec.cog_true_deg is not None:
                self.fixes.append((t, rec.sog_mps, rec.cog_true_deg))
            return
        if port == self.uut:
            for sp in speeds:
                lon, tr = sp.longitudinal_mps, sp.transverse_mps
                if sp.source == "VBW" and sp.valid and lon is not None and tr is not None:
                    self.read.append((t, lon, tr))
            return
        if not self.heads(port):
            return
        if isinstance(rec, Heading):
            self._heading(t, rec.heading_deg, rec.true, rec.variation_deg, rec.deviation_deg)
        for sp in speeds:
            if sp.heading_true_deg is not None:
                self.hdg.append((t, sp.heading_true_deg % 360.0))
            elif sp.heading_mag_deg is not None:
                self._heading(t, sp.heading_mag_deg, False, None, None)

    def _heading(
        self, t: float, deg: float | None, true: bool, var: float | None, dev: float | None
    ) -> None:
        if deg is None:
            return
        if true:
            self.hdg.append((t, deg % 360.0))
            return
        variation = var if var is not None else self.variation_deg
        if variation is None:
            self.magnetic += 1
            return
        self.hdg.append((t, (deg + (dev or 0.0) + variation) % 360.0))


def record_two_axis_gnss(
    path: str | Path,
    uut: str,
    gnss: str,
    *,
    heading: str | None = None,
    variation_deg: float | None = None,
    age_s: float = 0.0,
) -> TwoAxisRecording:
    """Decode one capture with a GNSS receiver and a heading as the two-axis reference
    (module docstring); records a decoder rejects are counted and skipped.

    Args:
        path: capture v1 file.
        uut: the log's port (VBW).
        gnss: the receiver's port (RMC or VTG).
        heading: the port whose heading is taken; None: any port but the log's and
            the receiver's.
        variation_deg: magnetic variation, + east, for magnetic headings sent without
            one.
        age_s: how old the fix's velocity is when it is received (the receiver's
            filter, its output delay and the transmission), s: the heading is taken
            at ``t − age_s``. In turns the hull turns under the velocity while it
            ages: at the figure-8's 0.17 rad/s, 0.8 s of age puts 0.2 m/s of a
            1.5 m/s velocity on the wrong axis.

    Raises:
        OfflineError: a port missing; no heading, with the reason (none sent, or only
            magnetic headings and no variation); no fix; the log sends no VBW.
    """
    reader = CaptureReader(path, errors="skip")
    missing = [p for p in (uut, gnss, heading) if p is not None and p not in reader.ports]
    if missing:
        raise OfflineError(
            f"{path}: no port {', '.join(missing)} (has {', '.join(reader.ports) or 'none'})"
        )
    got = _Collect(uut, gnss, heading, variation_deg)
    decoders = {
        p: make_decoder(reader.ports[p], p, errors="skip")
        for p in reader.ports
        if p in (uut, gnss) or got.heads(p)
    }
    for t, port, data, _ in reader.received():
        dec = decoders.get(port)
        if dec is not None:
            for rec in dec.feed(data):
                if not isinstance(rec, Rejected):
                    got.take(t, port, rec, tuple(dec.speed_records(rec)))
    if not got.read:
        raise OfflineError(f"{path}: {uut} sends no VBW with a transverse speed through the water")
    if not got.fixes:
        raise OfflineError(f"{path}: {gnss} sends no valid fix with a speed and course over ground")
    if not got.hdg:
        why = (
            f"only magnetic headings ({got.magnetic}) and no variation: pass --variation DEG"
            if got.magnetic
            else "no heading sent"
        )
        raise OfflineError(
            f"{path}: a GNSS reference needs the heading to turn its velocity into the hull "
            f"frame: {why}"
        )
    r, f, h = (
        a[np.argsort(a[:, 0], kind="stable")]
        for a in (
            np.asarray(got.read, dtype=np.float64),
            np.asarray(got.fixes, dtype=np.float64),
            np.asarray(got.hdg, dtype=np.float64),
        )
    )
    psi_deg = interpolate(
        h[:, 0],
        h[:, 1],
        np.ones(h.shape[0], dtype=bool),
        f[:, 0] - age_s,
        DEFAULT_MAX_GAP_S,
        angular=True,
    )
    cog, psi = np.radians(f[:, 2]), np.radians(psi_deg)
    ve, vn = f[:, 1] * np.sin(cog), f[:, 1] * np.cos(cog)
    return TwoAxisRecording(
        path=str(path),
        uut=uut,
        t_read=r[:, 0],
        raw_l=r[:, 1],
        raw_t=r[:, 2],
        t_ref=f[:, 0],
        ref_fwd=vn * np.cos(psi) + ve * np.sin(psi),
        ref_stb=-vn * np.sin(psi) + ve * np.cos(psi),
        heading=psi_deg,
        rejects={
            p: {str(k): v for k, v in d.counters.rejects.items()} for p, d in decoders.items()
        },
    )
