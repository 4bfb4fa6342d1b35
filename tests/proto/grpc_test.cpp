// The generated gRPC types of ruffini.v1.Aggregator (ruffini::grpc) compile, link and talk: a
// CallbackService answers over an in-process channel (no port), through the generated Stub.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <memory>

#include "ruffini/v1/aggregator.grpc.pb.h"

namespace {

using namespace ruffini;

// Implements two RPCs; the others keep the generated default (UNIMPLEMENTED).
class FakeAggregator final : public v1::Aggregator::CallbackService {
 public:
  grpc::ServerUnaryReactor* GetStatus(grpc::CallbackServerContext* context, const v1::GetStatusRequest*,
                                      v1::AggregatorStatus* response) override {
    response->set_t_ns(1'700'000'000'000'000'000);
    response->mutable_safety()->set_state(v1::SafetyState::STATE_FAULT);
    response->mutable_safety()->set_stop_epoch(1);
    auto* p = response->add_patches();
    p->set_patch_id("forearm");
    p->set_link_state(v1::LINK_STATE_HELLO_PENDING);
    response->set_joint_state_age_ns(-1);
    auto* reactor = context->DefaultReactor();
    reactor->Finish(grpc::Status::OK);
    return reactor;
  }

  grpc::ServerUnaryReactor* ResetStop(grpc::CallbackServerContext* context, const v1::ResetStopRequest* request,
                                      v1::ResetStopResponse* response) override {
    response->set_accepted(false);
    response->set_reason(request->stop_epoch() == 1 ? v1::RESET_REFUSAL_CAUSE_PRESENT : v1::RESET_REFUSAL_WRONG_EPOCH);
    response->mutable_state()->set_state(v1::SafetyState::STATE_FAULT);
    auto* reactor = context->DefaultReactor();
    reactor->Finish(grpc::Status::OK);
    return reactor;
  }
};

class AggregatorStubs : public ::testing::Test {
 protected:
  void SetUp() override {
    grpc::ServerBuilder builder;
    builder.RegisterService(&service_);
    server_ = builder.BuildAndStart();
    ASSERT_NE(server_, nullptr);
    stub_ = v1::Aggregator::NewStub(server_->InProcessChannel(grpc::ChannelArguments{}));
    ASSERT_NE(stub_, nullptr);
  }
  void TearDown() override {
    if (server_) server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(1));
  }
  static void Deadline(grpc::ClientContext& c) { c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5)); }

  FakeAggregator service_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<v1::Aggregator::Stub> stub_;
};

TEST_F(AggregatorStubs, UnaryCallsGoThroughTheGeneratedStub) {
  grpc::ClientContext ctx;
  Deadline(ctx);
  v1::AggregatorStatus status;
  ASSERT_TRUE(stub_->GetStatus(&ctx, v1::GetStatusRequest{}, &status).ok());
  EXPECT_EQ(status.safety().state(), v1::SafetyState::STATE_FAULT);
  ASSERT_EQ(status.patches_size(), 1);
  EXPECT_EQ(status.patches(0).patch_id(), "forearm");

  grpc::ClientContext ctx2;
  Deadline(ctx2);
  v1::ResetStopRequest req;
  req.set_stop_epoch(7);
  v1::ResetStopResponse resp;
  ASSERT_TRUE(stub_->ResetStop(&ctx2, req, &resp).ok());
  EXPECT_FALSE(resp.accepted());
  EXPECT_EQ(resp.reason(), v1::RESET_REFUSAL_WRONG_EPOCH);
}

TEST_F(AggregatorStubs, EveryStreamingSignatureIsGenerated) {
  // Not implemented by the fake: each returns UNIMPLEMENTED, which shows the method exists on both sides
  // with the contract's streaming shape (these calls only compile with the right request/response types).
  {
    grpc::ClientContext ctx;
    Deadline(ctx);
    std::unique_ptr<grpc::ClientReaderWriter<v1::PatchMessage, v1::AggregatorCommand>> s = stub_->Connect(&ctx);
    v1::PatchMessage hello;
    hello.set_patch_id("forearm");
    hello.set_seq(1);
    hello.mutable_hello()->set_patch_name("forearm");
    s->Write(hello);  // may fail once the server has finished the call; the status says why
    s->WritesDone();
    v1::AggregatorCommand cmd;
    EXPECT_FALSE(s->Read(&cmd));
    EXPECT_EQ(s->Finish().error_code(), grpc::StatusCode::UNIMPLEMENTED);
  }
  {
    grpc::ClientContext ctx;
    Deadline(ctx);
    v1::PublishJointStatesResponse resp;
    std::unique_ptr<grpc::ClientWriter<v1::JointState>> w = stub_->PublishJointStates(&ctx, &resp);
    w->WritesDone();
    EXPECT_EQ(w->Finish().error_code(), grpc::StatusCode::UNIMPLEMENTED);
  }
  {
    grpc::ClientContext ctx;
    Deadline(ctx);
    std::unique_ptr<grpc::ClientReader<v1::SafetyState>> r = stub_->WatchSafety(&ctx, v1::WatchSafetyRequest{});
    v1::SafetyState st;
    EXPECT_FALSE(r->Read(&st));
    EXPECT_EQ(r->Finish().error_code(), grpc::StatusCode::UNIMPLEMENTED);
  }
  {
    grpc::ClientContext ctx;
    Deadline(ctx);
    std::unique_ptr<grpc::ClientReader<v1::ContactSet>> r = stub_->WatchContacts(&ctx, v1::WatchContactsRequest{});
    v1::ContactSet set;
    EXPECT_FALSE(r->Read(&set));
    EXPECT_EQ(r->Finish().error_code(), grpc::StatusCode::UNIMPLEMENTED);
  }
}

}  // namespace
