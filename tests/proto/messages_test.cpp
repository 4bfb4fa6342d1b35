// The ruffini.v1 wire messages (patch.proto, aggregator.proto): every message survives a round trip with
// every field set (filled by reflection, so a field added later is covered without touching this file),
// enums start at a *_UNSPECIFIED zero, and FrameRejectReason mirrors ruffini::decode::Reason.
#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <memory>
#include <string>
#include <vector>

#include "ruffini/decode/pipeline.h"
#include "ruffini/v1/aggregator.pb.h"
#include "ruffini/v1/patch.pb.h"

namespace {

namespace pb = google::protobuf;
using namespace ruffini;

constexpr int kMaxDepth = 6;

// Sets one value of f (appends when repeated); values are distinct and never the field's default.
void Fill(pb::Message& m, int variant, int& counter, int depth);

void SetOne(pb::Message& m, const pb::FieldDescriptor* f, int variant, int& counter, int depth) {
  const pb::Reflection* r = m.GetReflection();
  const int c = ++counter;
  const bool rep = f->is_repeated();
  switch (f->cpp_type()) {
    case pb::FieldDescriptor::CPPTYPE_INT32:
      rep ? r->AddInt32(&m, f, -c) : r->SetInt32(&m, f, -c);
      break;
    case pb::FieldDescriptor::CPPTYPE_INT64:
      rep ? r->AddInt64(&m, f, 1'700'000'000'000'000'000LL + c) : r->SetInt64(&m, f, 1'700'000'000'000'000'000LL + c);
      break;
    case pb::FieldDescriptor::CPPTYPE_UINT32:
      rep ? r->AddUInt32(&m, f, static_cast<std::uint32_t>(c)) : r->SetUInt32(&m, f, static_cast<std::uint32_t>(c));
      break;
    case pb::FieldDescriptor::CPPTYPE_UINT64:
      rep ? r->AddUInt64(&m, f, 10'000'000'000ULL + static_cast<std::uint64_t>(c))
          : r->SetUInt64(&m, f, 10'000'000'000ULL + static_cast<std::uint64_t>(c));
      break;
    case pb::FieldDescriptor::CPPTYPE_DOUBLE:
      rep ? r->AddDouble(&m, f, 0.25 + c) : r->SetDouble(&m, f, 0.25 + c);
      break;
    case pb::FieldDescriptor::CPPTYPE_FLOAT:
      rep ? r->AddFloat(&m, f, 0.5f + static_cast<float>(c)) : r->SetFloat(&m, f, 0.5f + static_cast<float>(c));
      break;
    case pb::FieldDescriptor::CPPTYPE_BOOL:
      rep ? r->AddBool(&m, f, true) : r->SetBool(&m, f, true);
      break;
    case pb::FieldDescriptor::CPPTYPE_ENUM: {
      const pb::EnumDescriptor* e = f->enum_type();
      ASSERT_GE(e->value_count(), 2) << e->full_name();
      const pb::EnumValueDescriptor* v = e->value(1 + c % (e->value_count() - 1));  // never the zero value
      rep ? r->AddEnum(&m, f, v) : r->SetEnum(&m, f, v);
      break;
    }
    case pb::FieldDescriptor::CPPTYPE_STRING: {
      const std::string s = f->name() + "-" + std::to_string(c) + "-\xc3\xa9";  // non-ASCII UTF-8 too
      rep ? r->AddString(&m, f, s) : r->SetString(&m, f, s);
      break;
    }
    case pb::FieldDescriptor::CPPTYPE_MESSAGE: {
      ASSERT_LT(depth, kMaxDepth) << "message nesting too deep at " << f->full_name();
      pb::Message* sub = rep ? r->AddMessage(&m, f) : r->MutableMessage(&m, f);
      Fill(*sub, variant, counter, depth + 1);
      break;
    }
  }
}

// Every field, twice when repeated; of each oneof, the alternative `variant` picks.
void Fill(pb::Message& m, int variant, int& counter, int depth) {
  const pb::Descriptor* d = m.GetDescriptor();
  for (int i = 0; i < d->field_count(); ++i) {
    const pb::FieldDescriptor* f = d->field(i);
    if (const pb::OneofDescriptor* o = f->real_containing_oneof(); o && o->field(variant % o->field_count()) != f) {
      continue;
    }
    for (int k = 0; k < (f->is_repeated() ? 2 : 1); ++k) SetOne(m, f, variant, counter, depth);
  }
}

// Every field Fill set is present after the round trip (proto3 scalars: present = not the default).
void ExpectAllSet(const pb::Message& m, int variant, const std::string& path) {
  const pb::Descriptor* d = m.GetDescriptor();
  const pb::Reflection* r = m.GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const pb::FieldDescriptor* f = d->field(i);
    const std::string where = path + "." + f->name();
    if (const pb::OneofDescriptor* o = f->real_containing_oneof()) {
      if (o->field(variant % o->field_count()) != f) {
        EXPECT_FALSE(r->HasField(m, f)) << where;
        continue;
      }
    }
    if (f->is_repeated()) {
      ASSERT_EQ(r->FieldSize(m, f), 2) << where;
      if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) {
        for (int k = 0; k < 2; ++k) ExpectAllSet(r->GetRepeatedMessage(m, f, k), variant, where);
      }
    } else {
      ASSERT_TRUE(r->HasField(m, f)) << where;
      if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) ExpectAllSet(r->GetMessage(m, f), variant, where);
    }
  }
}

int MaxOneofSize(const pb::Descriptor* d, int depth = 0) {
  int n = 1;
  for (int i = 0; i < d->oneof_decl_count(); ++i) n = std::max(n, d->oneof_decl(i)->field_count());
  if (depth < kMaxDepth) {
    for (int i = 0; i < d->field_count(); ++i) {
      if (d->field(i)->message_type()) n = std::max(n, MaxOneofSize(d->field(i)->message_type(), depth + 1));
    }
  }
  return n;
}

std::vector<const pb::Descriptor*> MessagesOf(const pb::FileDescriptor* file) {
  std::vector<const pb::Descriptor*> out;
  for (int i = 0; i < file->message_type_count(); ++i) out.push_back(file->message_type(i));
  return out;
}

// Parameter: a .proto file's name, as protoc registered it.
class WireFile : public ::testing::TestWithParam<const char*> {
 protected:
  static const pb::FileDescriptor* File() {
    // Naming a message of each file links its generated code (and so registers its descriptor).
    static_cast<void>(v1::PatchMessage::descriptor());
    static_cast<void>(v1::SafetyState::descriptor());
    return pb::DescriptorPool::generated_pool()->FindFileByName(GetParam());
  }
};

TEST_P(WireFile, EveryMessageRoundTripsWithEveryFieldSet) {
  ASSERT_NE(File(), nullptr) << GetParam();
  const auto messages = MessagesOf(File());
  ASSERT_FALSE(messages.empty());
  for (const pb::Descriptor* d : messages) {
    SCOPED_TRACE(d->full_name());
    const pb::Message* prototype = pb::MessageFactory::generated_factory()->GetPrototype(d);
    ASSERT_NE(prototype, nullptr);
    for (int variant = 0; variant < MaxOneofSize(d); ++variant) {
      SCOPED_TRACE("oneof variant " + std::to_string(variant));
      std::unique_ptr<pb::Message> in(prototype->New());
      int counter = 0;
      Fill(*in, variant, counter, 0);
      std::string bytes;
      ASSERT_TRUE(in->SerializeToString(&bytes));
      std::unique_ptr<pb::Message> out(prototype->New());
      ASSERT_TRUE(out->ParseFromString(bytes));
      ExpectAllSet(*out, variant, d->name());
      EXPECT_TRUE(pb::util::MessageDifferencer::Equals(*in, *out)) << in->DebugString() << "\n---\n"
                                                                  << out->DebugString();
    }
  }
}

// buf lint checks this too; here it also holds where npm is missing.
TEST_P(WireFile, EveryEnumStartsAtUnspecified) {
  std::vector<const pb::EnumDescriptor*> enums;
  const pb::FileDescriptor* file = File();
  ASSERT_NE(file, nullptr) << GetParam();
  for (int i = 0; i < file->enum_type_count(); ++i) enums.push_back(file->enum_type(i));
  for (const pb::Descriptor* d : MessagesOf(file)) {
    for (int i = 0; i < d->enum_type_count(); ++i) enums.push_back(d->enum_type(i));
  }
  ASSERT_FALSE(enums.empty());
  for (const pb::EnumDescriptor* e : enums) {
    const pb::EnumValueDescriptor* zero = e->FindValueByNumber(0);
    ASSERT_NE(zero, nullptr) << e->full_name();
    EXPECT_TRUE(zero->name().ends_with("_UNSPECIFIED")) << e->full_name() << ": " << zero->name();
    EXPECT_EQ(e->value(0), zero) << e->full_name();
  }
}

INSTANTIATE_TEST_SUITE_P(Contracts, WireFile, ::testing::Values("ruffini/v1/patch.proto", "ruffini/v1/aggregator.proto"),
                         [](const auto& p) {
                           std::string n = p.param;
                           n = n.substr(n.rfind('/') + 1);
                           return n.substr(0, n.find('.'));
                         });

TEST(SafetyState, ZeroValueIsUnspecifiedAndNotClear) {
  EXPECT_EQ(v1::SafetyState::STATE_UNSPECIFIED, 0);
  EXPECT_EQ(v1::SafetyState().state(), v1::SafetyState::STATE_UNSPECIFIED);
  v1::SafetyState parsed;  // an empty message on the wire (every field at its default)
  ASSERT_TRUE(parsed.ParseFromString(std::string{}));
  EXPECT_EQ(parsed.state(), v1::SafetyState::STATE_UNSPECIFIED);
  EXPECT_NE(parsed.state(), v1::SafetyState::STATE_CLEAR);
  EXPECT_EQ(parsed.stop_epoch(), 0u);  // 0 never appears on a real state: unset
  // A state this reader does not know survives a round trip as its number (proto3 open enums) and is not CLEAR.
  v1::SafetyState future;
  future.set_state(static_cast<v1::SafetyState::State>(42));
  ASSERT_TRUE(parsed.ParseFromString(future.SerializeAsString()));
  EXPECT_EQ(static_cast<int>(parsed.state()), 42);
  EXPECT_FALSE(v1::SafetyState::State_IsValid(parsed.state()));
}

TEST(PatchMessage, ContactRoundTripsWithItsUnits) {
  v1::PatchMessage m;
  m.set_patch_id("forearm");
  m.set_seq(42);
  m.set_interrogator_serial(123456789);
  m.set_t_ns(1'700'000'000'123'456'789);
  m.set_decoder_t_ns(1'700'000'000'124'000'000);
  v1::PatchContact* c = m.mutable_contact();
  c->set_force_n(3.25f);
  c->set_force_sd_n(0.4f);
  c->set_located(true);
  c->set_y_mm(75.5f);
  c->set_r_deg(90.0f);
  c->set_cov_yy_mm2(4.0f);
  c->set_cov_yr_mm2(-0.5f);
  c->set_cov_rr_mm2(9.0f);
  c->set_confidence(0.8f);
  c->set_onset(true);
  v1::PatchMessage back;
  ASSERT_TRUE(back.ParseFromString(m.SerializeAsString()));
  EXPECT_EQ(back.body_case(), v1::PatchMessage::kContact);
  EXPECT_EQ(back.seq(), 42u);
  EXPECT_EQ(back.t_ns(), 1'700'000'000'123'456'789);
  EXPECT_FLOAT_EQ(back.contact().force_n(), 3.25f);
  EXPECT_FLOAT_EQ(back.contact().cov_yr_mm2(), -0.5f);
  EXPECT_TRUE(back.contact().onset());
  EXPECT_FALSE(back.contact().released());
  // A message with no body (a malformed one) says so.
  EXPECT_EQ(v1::PatchMessage().body_case(), v1::PatchMessage::BODY_NOT_SET);
}

// Issue 17: the faint flag round trips on its own (PatchContact 18, BodyContact 16), next to `multiple`, and a
// contact from a sender that never sets it reads as not faint.
TEST(PatchMessage, TheFaintFlagRoundTripsOnPatchAndBodyContacts) {
  v1::PatchMessage m;
  m.mutable_contact()->set_force_n(1.75f);
  m.mutable_contact()->set_faint(true);
  v1::PatchMessage back;
  ASSERT_TRUE(back.ParseFromString(m.SerializeAsString()));
  EXPECT_TRUE(back.contact().faint());
  EXPECT_FALSE(back.contact().multiple());
  EXPECT_FLOAT_EQ(back.contact().force_n(), 1.75f);
  m.mutable_contact()->set_faint(false);
  ASSERT_TRUE(back.ParseFromString(m.SerializeAsString()));
  EXPECT_FALSE(back.contact().faint());
  EXPECT_EQ(v1::PatchContact::kFaintFieldNumber, 18);
  v1::BodyContact b;
  b.set_force_n(1.75f);
  b.set_faint(true);
  v1::BodyContact body_back;
  ASSERT_TRUE(body_back.ParseFromString(b.SerializeAsString()));
  EXPECT_TRUE(body_back.faint());
  EXPECT_FALSE(body_back.multiple());
  EXPECT_EQ(v1::BodyContact::kFaintFieldNumber, 16);
}

// FrameRejectReason 1..8 are decode::Reason's values with the same numbers and names, so a decoder maps
// one to the other with a cast, and its metric labels (ReasonName) match the wire names.
TEST(FrameRejectReason, MirrorsDecodeReason) {
  static_assert(decode::kReasonCount == 9, "decode::Reason changed: update FrameRejectReason in patch.proto");
  const pb::EnumDescriptor* e = v1::FrameRejectReason_descriptor();
  for (std::size_t i = 1; i < decode::kReasonCount; ++i) {
    const auto r = static_cast<decode::Reason>(i);
    std::string expected = "FRAME_REJECT_REASON_";
    for (char ch : decode::ReasonName(r)) expected += static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
    const pb::EnumValueDescriptor* v = e->FindValueByNumber(static_cast<int>(i));
    ASSERT_NE(v, nullptr) << expected;
    EXPECT_EQ(v->name(), expected);
  }
  // decode::Reason::kOk has no rejection: the zero value.
  EXPECT_EQ(e->FindValueByNumber(0)->name(), "FRAME_REJECT_REASON_UNSPECIFIED");
  // The interrogator stream's own reasons start at 32, clear of decode::Reason's range.
  for (int i = 0; i < e->value_count(); ++i) {
    const int n = e->value(i)->number();
    EXPECT_TRUE(n < static_cast<int>(decode::kReasonCount) || n >= 32) << e->value(i)->name();
  }
}

}  // namespace
