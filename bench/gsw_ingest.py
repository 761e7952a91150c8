"""Ingest rate of the GSW archive: parse + decoded fields into SQLite, with telemetry authentication
on and off, against a raw batched insert.

The runs take the same telemetry (a mix of every housekeeping kind, tree status, events and link
statistics), pre-encoded, in the same process, one after the other:

* ``archive, TM auth on``: what the GSW link does per received datagram: ``parse_datagram`` with
  the telemetry verifier (CRC, header, key, HMAC-SHA256, replay window, fields) and
  ``Recorder.record`` (raw packet row + one row per decoded field, batched transactions, WAL), on
  packets signed as the CRS signs them;
* ``archive, TM auth off``: the same without security header and MAC (the unauthenticated form);
* ``raw``: the floor: the signed bytes inserted as (time, blob) rows with ``executemany`` in
  batches of the same size, WAL mode, no parsing.

Prints packets/s for each, the ratio of authentication on to off and of the archive to raw, and
checks zero loss (every packet and every field row is in the database afterwards). Goals (issues 7
and 66): >= 20,000 packets/s with decoded fields, with telemetry authentication on.

    .venv/bin/python bench/gsw_ingest.py [--packets 100000] [--batch 1000]
"""

from __future__ import annotations

import argparse
import os
import sqlite3
import tempfile
import time
from pathlib import Path

from tlt_common.ccsds.auth import KeyRing
from tlt_common.ccsds.codec import Packet, encode_telemetry, parse_datagram
from tlt_common.ccsds.definitions import INTEGER_TYPES, Definitions, FieldDef, load_definitions
from tlt_common.ccsds.tm_security import TelemetrySigner, TelemetryVerifier
from tlt_gsw.archive import Recorder


def _value(fd: FieldDef, i: int):
    if fd.type in INTEGER_TYPES:
        return i % min(INTEGER_TYPES[fd.type][1], 1000)
    if fd.type in ("f32", "f64"):
        return 0.001 * (i % 1000)
    if fd.type == "bool":
        return i % 2 == 0
    if fd.type == "enum":
        return fd.enum[i % len(fd.enum)]
    if fd.type == "string":
        return f"step {i % 97}"
    return bytes(16)


def make_datagrams(
    defs: Definitions, count: int, signer: TelemetrySigner | None = None
) -> tuple[list[bytes], int]:
    """``count`` telemetry datagrams, signed by ``signer`` (authentication on) or not."""
    kinds = [k for k in defs.telemetry if k != "ack"]
    seq: dict[str, int] = {}
    out, fields = [], 0
    t0 = time.time()
    for i in range(count):
        kind = kinds[i % len(kinds)]
        pdef = defs.packet(kind)
        values = {fd.name: _value(fd, i) for fd in pdef.fields}
        n = seq.get(kind, 0)
        seq[kind] = (n + 1) % 16384
        stamp = t0 + i * 1e-4
        if signer is None:
            out.append(encode_telemetry(defs, kind, values, seq_count=n, timestamp=stamp))
        else:
            out.append(signer.encode(defs, kind, values, seq_count=n, timestamp=stamp))
        fields += len(values)
    return out, fields


def run_archive(
    path: Path, datagrams: list[bytes], defs: Definitions, batch: int, verifier: TelemetryVerifier | None
) -> tuple[float, float]:
    rec = Recorder(path, batch_size=batch, flush_interval_s=3600)
    start, cpu = time.perf_counter(), time.process_time()
    for raw in datagrams:
        rec.record("rx", raw, parse_datagram(raw, defs, keyring=verifier, replay=verifier))
    rec.flush()
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    rec.close()
    return elapsed, cpu


def run_raw(path: Path, datagrams: list[bytes], batch: int) -> tuple[float, float]:
    conn = sqlite3.connect(path, isolation_level=None)
    conn.execute("PRAGMA journal_mode=WAL")
    conn.execute("PRAGMA synchronous=NORMAL")
    conn.execute(
        "CREATE TABLE raw_packets (id INTEGER PRIMARY KEY, recorded_at REAL NOT NULL, raw BLOB NOT NULL)"
    )
    start, cpu = time.perf_counter(), time.process_time()
    for i in range(0, len(datagrams), batch):
        now = time.time()
        conn.execute("BEGIN")
        conn.executemany(
            "INSERT INTO raw_packets (recorded_at, raw) VALUES (?, ?)",
            [(now, raw) for raw in datagrams[i : i + batch]],
        )
        conn.execute("COMMIT")
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    stored = conn.execute("SELECT COUNT(*) FROM raw_packets").fetchone()[0]
    conn.close()
    if stored != len(datagrams):
        raise SystemExit(f"raw insert lost packets: {stored} of {len(datagrams)}")
    return elapsed, cpu


def _stored(path: Path) -> tuple[int, int, float]:
    conn = sqlite3.connect(path)
    packets = conn.execute("SELECT COUNT(*) FROM packets WHERE status = 'ok'").fetchone()[0]
    fields = conn.execute("SELECT COUNT(*) FROM fields").fetchone()[0]
    conn.close()
    return packets, fields, path.stat().st_size / 1e6


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--packets", type=int, default=100_000)
    parser.add_argument("--batch", type=int, default=1000)
    args = parser.parse_args(argv)
    defs = load_definitions()
    ring = KeyRing({1: os.urandom(32)}, {1: os.urandom(32)})
    signed, field_count = make_datagrams(defs, args.packets, TelemetrySigner(ring.telemetry, 1))
    plain, _ = make_datagrams(defs, args.packets)
    check = TelemetryVerifier(ring.telemetry)
    parse_ok = sum(
        isinstance(parse_datagram(d, defs, keyring=check, replay=check), Packet) for d in signed[:1000]
    )
    parse_ok += sum(isinstance(parse_datagram(d, defs), Packet) for d in plain[:1000])
    assert parse_ok == 2 * min(1000, len(signed)), "bench datagrams must all be valid"
    with tempfile.TemporaryDirectory() as tmp:
        on_db, off_db, raw_db = (Path(tmp) / f"{name}.sqlite" for name in ("auth_on", "auth_off", "raw"))
        raw_s, raw_cpu = run_raw(raw_db, signed, args.batch)
        off_s, off_cpu = run_archive(off_db, plain, defs, args.batch, None)
        on_s, on_cpu = run_archive(on_db, signed, defs, args.batch, TelemetryVerifier(ring.telemetry))
        packets, fields, size_mb = _stored(on_db)
        off_packets, off_fields, _ = _stored(off_db)
    n = len(signed)
    on_rate, off_rate, raw_rate = n / on_s, n / off_s, n / raw_s
    loss = (n - packets) + (field_count - fields)
    off_loss = (n - off_packets) + (field_count - off_fields)
    load = os.getloadavg()[0]
    print(
        f"packets: {n} ({field_count} decoded fields, {field_count / n:.1f} per packet), batch {args.batch}"
    )
    print(
        f"machine: {os.cpu_count()} CPU(s), 1-min load average {load:.1f} (figures per CPU-second are less "
        "sensitive to other load)"
    )
    print(
        f"raw batched insert         : {raw_rate:12,.0f} packets/s wall ({raw_s:.2f} s), "
        f"{n / raw_cpu:,.0f} per CPU-second"
    )
    print(
        f"archive, TM auth off       : {off_rate:12,.0f} packets/s wall ({off_s:.2f} s), "
        f"{n / off_cpu:,.0f} per CPU-second"
    )
    print(
        f"archive, TM auth on        : {on_rate:12,.0f} packets/s wall ({on_s:.2f} s), "
        f"{n / on_cpu:,.0f} per CPU-second, {fields / on_s:,.0f} field rows/s, archive {size_mb:.1f} MB"
    )
    print(f"ratio TM auth on / off     : {on_rate / off_rate:.3f} wall, {off_cpu / on_cpu:.3f} CPU")
    print(f"ratio archive / raw        : {on_rate / raw_rate:.3f} wall, {raw_cpu / on_cpu:.3f} CPU")
    print(
        f"loss                       : {loss} (packets stored {packets}/{n}, fields {fields}/{field_count}); "
        f"with TM auth off {off_loss}"
    )
    goal = on_rate >= 20_000 and loss == 0 and off_loss == 0
    print(f"goal >= 20,000 packets/s (wall, TM auth on) with zero loss: {'met' if goal else 'NOT met'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
