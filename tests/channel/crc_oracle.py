#!/usr/bin/env python3
"""A second, independent implementation of the safety CRC's canonical layout (docs/safety-channel.md), in
Python with zlib's CRC-32, for the test vectors in crc_test.cpp. Run it to print the vectors; the C++ test
asserts the same numbers, so the layout is pinned by two implementations that share no code."""
import struct
import zlib


def u64(v): return struct.pack('<Q', v & 0xFFFFFFFFFFFFFFFF)
def i64(v): return struct.pack('<q', v)
def u32(v): return struct.pack('<I', v & 0xFFFFFFFF)
def i32(v): return struct.pack('<i', v)
def b(v): return b'\x01' if v else b'\x00'
def f32(v): return struct.pack('<f', v)
def f64(v): return struct.pack('<d', v)
def s(v): e = v.encode(); return u32(len(e)) + e


def contact_message():
    # PatchMessage{patch_id "forearm_a", seq 7, serial 1234, t_ns 1700000000000000000, decoder_t_ns
    # 1700000000000100000, sender_run_id 0x0123456789abcdef, sender_steady_ns 5000000000,
    # aggregator_run_id 0xfedcba9876543210, contact{force 2.5, sd 0.125, located, y 75.5, r 42.25,
    # cov 4, 0.5, 9, confidence 0.75, onset, !released, common_mode -1.5, missing 0, calibrated,
    # over_range, force_lower_bound 2.5, multiple, faint}}
    out = s('forearm_a') + u64(7) + u64(1234) + i64(1700000000000000000) + i64(1700000000000100000)
    out += u64(0x0123456789abcdef) + i64(5000000000) + u64(0xfedcba9876543210) + u32(11)
    out += f32(2.5) + f32(0.125) + b(True) + f32(75.5) + f32(42.25) + f32(4.0) + f32(0.5) + f32(9.0)
    out += f32(0.75) + b(True) + b(False) + f32(-1.5) + u32(0) + b(True) + b(True) + f32(2.5) + b(True)
    out += b(True)
    return out


def heartbeat_message():
    # PatchMessage{patch_id "p", seq 2, sender_run_id 1, sender_steady_ns 10, aggregator_run_id 2,
    # heartbeat{healthy, active_fault 0, frames 100, valid 99, gaps 0, lost 0, rejected [{reason 3, 1}],
    # onsets 0, !in_contact, baseline_state 2 (TRACKING), drift 0.25, common_mode 0, frozen 0, dropped 0}}
    out = s('p') + u64(2) + u64(0) + i64(0) + i64(0) + u64(1) + i64(10) + u64(2) + u32(12)
    out += b(True) + i32(0) + u64(100) + u64(99) + u64(0) + u64(0) + u32(1) + i32(3) + u64(1)
    out += u64(0) + b(False) + i32(2) + f32(0.25) + f32(0.0) + f32(0.0) + u64(0)
    return out


def safety_state():
    # SafetyState{STOP, epoch 3, seq 42, changed 100, published 200, start 50, run 0x1122334455667788,
    # robot "cobot", sender_steady_ns 123456789, cause{CONTACT, patch "forearm_a", region "forearm",
    # link "forearm_link", force 3, threshold 1.5, p (0.1, -0.2, 0.3), patch_fault 0, t_ns 99}}
    out = i32(2) + u64(3) + u64(42) + i64(100) + i64(200) + i64(50) + u64(0x1122334455667788)
    out += s('cobot') + i64(123456789)
    out += i32(1) + s('forearm_a') + s('forearm') + s('forearm_link') + f32(3.0) + f32(1.5)
    out += f64(0.1) + f64(-0.2) + f64(0.3) + i32(0) + i64(99)
    return out


# The values crc_test.cpp asserts (kContactCrc, kHeartbeatCrc, kStateCrc).
EXPECTED = {'contact': 0xE68ED30C, 'heartbeat': 0x0A8F8F41, 'state': 0x2A93C49F}

if __name__ == '__main__':
    import sys
    bad = 0
    for name, fn in (('contact', contact_message), ('heartbeat', heartbeat_message), ('state', safety_state)):
        crc = zlib.crc32(fn())
        print(f'{name} 0x{crc:08X}')
        if '--check' in sys.argv and crc != EXPECTED[name]:
            print(f'  expected 0x{EXPECTED[name]:08X}', file=sys.stderr)
            bad += 1
    sys.exit(1 if bad else 0)
