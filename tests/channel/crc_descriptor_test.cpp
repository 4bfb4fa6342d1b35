// The CRC's field list against the messages' descriptors: every field the .proto files declare, in every body
// and nested message a PatchMessage or a SafetyState can carry, either changes the safety CRC when it changes, or
// is on the short list of fields deliberately outside it (kOutsideTheCrc). A field added to the .proto without
// being added to crc.cpp, or to that list with a reason in docs/safety-channel.md, fails here (review 8's open
// point: the hand-written mutation lists of crc_test.cpp only cover the fields someone remembered).
#include <gtest/gtest.h>

#include <set>
#include <string>
#include <utility>
#include <vector>

#include "ruffini/channel/crc.h"

namespace ruffini::channel {
namespace {

using google::protobuf::Descriptor;
using google::protobuf::FieldDescriptor;
using google::protobuf::Message;
using google::protobuf::Reflection;

// Deliberately not covered (docs/safety-channel.md, "The CRC"): the CRC field itself, free text for people, and
// the seam partner (information for people and the demo's report; no controller may act on it).
const std::set<std::string> kOutsideTheCrc = {
    "ruffini.v1.PatchMessage.safety_crc32", "ruffini.v1.SafetyState.safety_crc32", "ruffini.v1.PatchFault.message",
    "ruffini.v1.SafetyCause.message",      "ruffini.v1.SafetyCause.seam_partner_patch_id",
};

// A way from the root message to a nested one: each step a field and, for a repeated field, the element.
using Path = std::vector<std::pair<const FieldDescriptor*, int>>;

Message* Navigate(Message& root, const Path& path) {
  Message* m = &root;
  for (const auto& [f, index] : path) {
    const Reflection* r = m->GetReflection();
    m = f->is_repeated() ? r->MutableRepeatedMessage(m, f, index) : r->MutableMessage(m, f);
  }
  return m;
}

// Changes one singular scalar field to another value of its type.
void Mutate(Message& m, const FieldDescriptor* f) {
  const Reflection* r = m.GetReflection();
  switch (f->cpp_type()) {
    case FieldDescriptor::CPPTYPE_INT32: r->SetInt32(&m, f, r->GetInt32(m, f) + 1); break;
    case FieldDescriptor::CPPTYPE_INT64: r->SetInt64(&m, f, r->GetInt64(m, f) + 1); break;
    case FieldDescriptor::CPPTYPE_UINT32: r->SetUInt32(&m, f, r->GetUInt32(m, f) + 1); break;
    case FieldDescriptor::CPPTYPE_UINT64: r->SetUInt64(&m, f, r->GetUInt64(m, f) + 1); break;
    case FieldDescriptor::CPPTYPE_FLOAT: r->SetFloat(&m, f, r->GetFloat(m, f) + 0.5f); break;
    case FieldDescriptor::CPPTYPE_DOUBLE: r->SetDouble(&m, f, r->GetDouble(m, f) + 0.5); break;
    case FieldDescriptor::CPPTYPE_BOOL: r->SetBool(&m, f, !r->GetBool(m, f)); break;
    case FieldDescriptor::CPPTYPE_STRING: r->SetString(&m, f, r->GetString(m, f) + "x"); break;
    case FieldDescriptor::CPPTYPE_ENUM: {
      const auto* e = f->enum_type();
      const int next = (r->GetEnum(m, f)->index() + 1) % e->value_count();
      r->SetEnum(&m, f, e->value(next));
      break;
    }
    case FieldDescriptor::CPPTYPE_MESSAGE: ADD_FAILURE() << f->full_name() << ": not a scalar"; break;
  }
}

// Appends one element (a default one) to a repeated field.
void Append(Message& m, const FieldDescriptor* f) {
  const Reflection* r = m.GetReflection();
  switch (f->cpp_type()) {
    case FieldDescriptor::CPPTYPE_INT32: r->AddInt32(&m, f, 1); break;
    case FieldDescriptor::CPPTYPE_INT64: r->AddInt64(&m, f, 1); break;
    case FieldDescriptor::CPPTYPE_UINT32: r->AddUInt32(&m, f, 1); break;
    case FieldDescriptor::CPPTYPE_UINT64: r->AddUInt64(&m, f, 1); break;
    case FieldDescriptor::CPPTYPE_FLOAT: r->AddFloat(&m, f, 1.0f); break;
    case FieldDescriptor::CPPTYPE_DOUBLE: r->AddDouble(&m, f, 1.0); break;
    case FieldDescriptor::CPPTYPE_BOOL: r->AddBool(&m, f, true); break;
    case FieldDescriptor::CPPTYPE_STRING: r->AddString(&m, f, "x"); break;
    case FieldDescriptor::CPPTYPE_ENUM: r->AddEnum(&m, f, f->enum_type()->value(f->enum_type()->value_count() - 1)); break;
    case FieldDescriptor::CPPTYPE_MESSAGE: r->AddMessage(&m, f); break;
  }
}

template <class Root>
struct Walker {
  std::vector<std::string> uncovered;      // changed, CRC unchanged, not on the list
  std::vector<std::string> listed_covered;  // on the list, yet the CRC changed
  std::set<std::string> checked;

  void Check(const Root& base, const Root& changed, const FieldDescriptor* f, const std::string& what) {
    checked.insert(f->full_name());
    const bool covered = SafetyCrc(changed) != SafetyCrc(base);
    const bool outside = kOutsideTheCrc.count(f->full_name()) > 0;
    if (!covered && !outside) uncovered.push_back(what);
    if (covered && outside) listed_covered.push_back(what);
  }

  // Every field of the message at `path` in `base` (which holds that message: its oneof case selected).
  void Walk(const Root& base, const Path& path, int depth) {
    ASSERT_LT(depth, 8) << "nesting deeper than any message here: a recursive type?";
    Root probe = base;
    const Descriptor* d = Navigate(probe, path)->GetDescriptor();
    for (int i = 0; i < d->field_count(); ++i) {
      const FieldDescriptor* f = d->field(i);
      if (f->is_repeated()) {
        Root changed = base;
        Append(*Navigate(changed, path), f);
        Check(base, changed, f, f->full_name() + " (one element more)");
        if (f->cpp_type() == FieldDescriptor::CPPTYPE_MESSAGE) {
          Path p = path;
          p.emplace_back(f, Navigate(changed, path)->GetReflection()->FieldSize(*Navigate(changed, path), f) - 1);
          Walk(changed, p, depth + 1);  // each field of that element
        }
        continue;
      }
      if (f->cpp_type() == FieldDescriptor::CPPTYPE_MESSAGE) {
        Root holding = base;
        Path p = path;
        p.emplace_back(f, -1);
        Navigate(holding, p);  // present (for a oneof member: that body selected)
        Walk(holding, p, depth + 1);
        continue;
      }
      Root changed = base;
      Mutate(*Navigate(changed, path), f);
      Check(base, changed, f, f->full_name());
    }
  }
};

std::string Join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += "\n  " + x;
  return s;
}

TEST(SafetyCrcDescriptor, EveryFieldOfEveryPatchMessageBodyIsCoveredOrListedAsOutside) {
  v1::PatchMessage base;
  base.set_patch_id("forearm_a");
  base.set_seq(7);
  Walker<v1::PatchMessage> w;
  w.Walk(base, {}, 0);
  EXPECT_TRUE(w.uncovered.empty()) << "fields whose change leaves the CRC unchanged (add them to crc.cpp, or to "
                                      "kOutsideTheCrc with a reason in docs/safety-channel.md):"
                                   << Join(w.uncovered);
  EXPECT_TRUE(w.listed_covered.empty()) << "listed as outside the CRC but covered:" << Join(w.listed_covered);
  // The walk reached every body (a field of each).
  for (const char* f : {"ruffini.v1.PatchContact.force_n", "ruffini.v1.Heartbeat.healthy", "ruffini.v1.PatchFault.code",
                        "ruffini.v1.PatchHello.patch_name", "ruffini.v1.RetareResult.outcome"}) {
    EXPECT_TRUE(w.checked.count(f)) << f << " not reached";
  }
}

TEST(SafetyCrcDescriptor, EveryFieldOfASafetyStateIsCoveredOrListedAsOutside) {
  v1::SafetyState base;
  base.set_state(v1::SafetyState::STATE_STOP);
  Walker<v1::SafetyState> w;
  w.Walk(base, {}, 0);
  EXPECT_TRUE(w.uncovered.empty()) << "fields whose change leaves the CRC unchanged:" << Join(w.uncovered);
  EXPECT_TRUE(w.listed_covered.empty()) << "listed as outside the CRC but covered:" << Join(w.listed_covered);
  EXPECT_TRUE(w.checked.count("ruffini.v1.SafetyCause.seam_partner_patch_id"));
  EXPECT_TRUE(w.checked.count("ruffini.v1.SafetyCause.force_n"));
}

}  // namespace
}  // namespace ruffini::channel
