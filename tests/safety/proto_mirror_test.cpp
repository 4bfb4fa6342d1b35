// The policy's enums mirror ruffini.v1 one to one: the same numbers, and each *Name() is the wire name's
// suffix in lower case, so the aggregator service converts with a cast and its metric labels match the wire.
#include <gtest/gtest.h>

#include <cctype>
#include <string>

#include "ruffini/safety/policy.h"
#include "ruffini/v1/aggregator.pb.h"
#include "ruffini/v1/patch.pb.h"

namespace ruffini::safety {
namespace {

namespace pb = google::protobuf;
namespace v1 = ruffini::v1;

std::string Upper(std::string_view s) {
  std::string out;
  for (char ch : s) out += static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
  return out;
}

// Every value 0..count-1 of E is the proto value with that number and name, and the proto has no other.
template <typename E>
void ExpectMirror(const pb::EnumDescriptor* e, const std::string& prefix, std::size_t count,
                  std::string_view (*name)(E) noexcept) {
  EXPECT_EQ(static_cast<std::size_t>(e->value_count()), count) << e->full_name();
  for (std::size_t i = 0; i < count; ++i) {
    const pb::EnumValueDescriptor* v = e->FindValueByNumber(static_cast<int>(i));
    ASSERT_NE(v, nullptr) << e->full_name() << " has no value " << i;
    EXPECT_EQ(v->name(), prefix + Upper(name(static_cast<E>(i)))) << e->full_name();
  }
}

TEST(SafetyProtoMirror, State) {
  ExpectMirror<State>(v1::SafetyState::State_descriptor(), "STATE_", 4, &StateName);
  EXPECT_EQ(static_cast<int>(State::kClear), v1::SafetyState::STATE_CLEAR);
  EXPECT_EQ(static_cast<int>(State::kStop), v1::SafetyState::STATE_STOP);
  EXPECT_EQ(static_cast<int>(State::kFault), v1::SafetyState::STATE_FAULT);
}

TEST(SafetyProtoMirror, CauseKind) {
  ExpectMirror<CauseKind>(v1::SafetyCause::Kind_descriptor(), "KIND_", kCauseKindCount, &CauseKindName);
}

TEST(SafetyProtoMirror, ResetRefusal) {
  ExpectMirror<ResetRefusal>(v1::ResetRefusal_descriptor(), "RESET_REFUSAL_", kResetRefusalCount, &ResetRefusalName);
}

TEST(SafetyProtoMirror, LinkState) {
  ExpectMirror<LinkState>(v1::LinkState_descriptor(), "LINK_STATE_", kLinkStateCount, &LinkStateName);
}

TEST(SafetyProtoMirror, PatchFaultCode) {
  ExpectMirror<PatchFaultCode>(v1::PatchFaultCode_descriptor(), "PATCH_FAULT_CODE_", kPatchFaultCodeCount,
                               &PatchFaultCodeName);
}

}  // namespace
}  // namespace ruffini::safety
