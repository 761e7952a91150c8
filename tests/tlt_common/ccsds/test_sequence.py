"""14-bit sequence counts: issuing per APID and gap accounting with wraparound."""

from __future__ import annotations

from tlt_common.ccsds.codec import Rejection, encode_telemetry, parse_datagram
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.ccsds.reasons import Reason
from tlt_common.ccsds.sequence import SEQ_MODULO, GapTracker, SequenceCounters
from tlt_common.ccsds.stats import MAX_TRACKED_SOURCES, LinkStats


def test_counters_are_per_apid_and_wrap():
    counters = SequenceCounters()
    assert [counters.next(0x40) for _ in range(3)] == [0, 1, 2]
    assert counters.next(0x41) == 0
    for _ in range(SEQ_MODULO - 3):
        counters.next(0x40)
    assert counters.next(0x40) == 0


def test_in_order_stream_across_wraparound_has_no_gap():
    tracker = GapTracker()
    for seq in [*range(16380, 16384), *range(0, 5)]:
        assert tracker.observe(1, seq).missing == 0
    assert (tracker.gaps, tracker.missing) == (0, 0)


def test_gaps_are_counted_with_missing_packets_including_across_wrap():
    tracker = GapTracker()
    tracker.observe(1, 10)
    assert tracker.observe(1, 13).missing == 2
    tracker.observe(1, 16382)  # a jump of 16369 back-distance is a late packet, not a gap
    assert tracker.late == 1
    tracker = GapTracker()
    tracker.observe(2, 16382)
    assert tracker.observe(2, 1).missing == 2  # 16383 and 0 lost
    assert (tracker.gaps, tracker.missing) == (1, 2)


def test_duplicates_and_late_packets_do_not_move_the_count():
    tracker = GapTracker()
    tracker.observe(3, 100)
    assert tracker.observe(3, 100).duplicate
    assert tracker.observe(3, 99).late
    assert tracker.observe(3, 101).missing == 0
    assert (tracker.gaps, tracker.duplicates, tracker.late) == (0, 1, 1)


def test_apids_are_tracked_independently():
    tracker = GapTracker()
    tracker.observe(1, 0)
    tracker.observe(2, 500)
    assert tracker.observe(1, 1).missing == 0
    assert tracker.observe(2, 501).missing == 0
    tracker.reset(2)
    assert tracker.observe(2, 7).missing == 0


def test_link_stats_count_packets_gaps_crc_errors_and_rejections():
    defs = load_definitions()
    stats = LinkStats()
    values = {"member_count": 1, "member_states": b"\x01"}
    raws = [encode_telemetry(defs, "hk_tower", values, seq_count=s) for s in (16383, 0, 3)]
    for raw in raws:
        stats.record_rx(len(raw), parse_datagram(raw, defs))
    corrupted = raws[0][:-1] + bytes([raws[0][-1] ^ 0xFF])
    result = parse_datagram(corrupted, defs)
    assert isinstance(result, Rejection) and result.reason is Reason.BAD_CRC
    stats.record_rx(len(corrupted), result)
    fields = stats.as_fields()
    assert fields["packets_rx"] == 4 and fields["bytes_rx"] == sum(map(len, raws)) + len(corrupted)
    assert (fields["gaps"], fields["missing"], fields["crc_errors"], fields["rejections"]) == (1, 2, 1, 1)
    assert stats.by_reason == {"bad_crc": 1}


def test_drops_from_foreign_sources_are_counted_per_source_within_a_bound():
    stats = LinkStats()
    for port in range(MAX_TRACKED_SOURCES + 10):
        stats.record_foreign(10, ("10.0.0.9", 4000 + port))
    stats.record_foreign(10, ("10.0.0.9", 4000))
    assert stats.by_source["10.0.0.9:4000"] == 2 and stats.by_source["other"] == 10
    assert len(stats.by_source) == MAX_TRACKED_SOURCES + 1
    fields = stats.as_fields()
    assert (fields["source_rejections"], fields["rejections"], fields["packets_rx"]) == (75, 75, 75)
    assert stats.by_reason == {"source": 75} and stats.auth_rejections == 0
