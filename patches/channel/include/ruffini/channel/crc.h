// The safety layer's integrity measure: one CRC-32 over a message's safety-relevant fields, in a canonical
// byte order that does not depend on protobuf's serialisation (which is not canonical across versions and
// languages). docs/safety-channel.md lists the fields and the byte layout; tests/channel/crc_test.cpp pins
// them with test vectors, so a second implementation (the Python example) can be checked against them.
//
// The layout, field by field in the order below: unsigned and signed integers as little-endian two's
// complement of their proto width (uint64/int64/fixed64: 8 bytes, uint32/int32/enums: 4 bytes), bool as one
// byte 0/1, float/double as the little-endian bytes of their IEEE 754 bit pattern, a string as its length
// (4 bytes) then its bytes. The polynomial is CRC-32/IEEE 802.3 (the one zlib, Ethernet and PNG use:
// reflected 0x04C11DB7, init and final XOR 0xFFFFFFFF), via Boost.CRC.
//
// Real-time safe: no allocation, no lock, no throw.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "ruffini/v1/aggregator.pb.h"
#include "ruffini/v1/patch.pb.h"

namespace ruffini::channel {

// CRC-32/IEEE 802.3 of raw bytes ("123456789" -> 0xCBF43926, the catalogue's check value).
[[nodiscard]] std::uint32_t Crc32(std::span<const std::byte> bytes) noexcept;

// The CRC over a PatchMessage's safety-relevant fields (everything but `safety_crc32` and free text).
[[nodiscard]] std::uint32_t SafetyCrc(const v1::PatchMessage& m) noexcept;
// The CRC over a SafetyState's safety-relevant fields (everything but `safety_crc32` and cause.message).
[[nodiscard]] std::uint32_t SafetyCrc(const v1::SafetyState& s) noexcept;

// Sets safety_crc32 (call it last, after every other field is set).
void Seal(v1::PatchMessage& m) noexcept;
void Seal(v1::SafetyState& s) noexcept;

// Whether safety_crc32 matches the fields.
[[nodiscard]] bool CrcMatches(const v1::PatchMessage& m) noexcept;
[[nodiscard]] bool CrcMatches(const v1::SafetyState& s) noexcept;

}  // namespace ruffini::channel
