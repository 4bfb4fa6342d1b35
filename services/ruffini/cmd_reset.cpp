// ruffini reset: the operator's ResetStop. Reads the current stop_epoch (GetStatus) unless --epoch names one,
// asks for the reset, and prints the aggregator's answer. With --wait-s it retries every 100 ms while the
// aggregator refuses for a reason that time can cure (cause still present, not healthy long enough).
// Exit codes: 0 accepted (or already CLEAR), 4 refused (the message says why), 1 bad input or no aggregator.
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>

#include "commands.h"
#include "ruffini/error.h"
#include "ruffini/service/common.h"
#include "ruffini/service/tls.h"
#include "ruffini/v1/aggregator.grpc.pb.h"

namespace ruffini::cli {

void RegisterResetCommand(CLI::App& app) {
  struct Args {
    std::string aggregator, tls_dir, operator_name = "ruffini reset", note;
    bool insecure = false;
    long long epoch = -1;
    double wait_s = 0;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "reset", "The operator's ResetStop: clear a latched STOP or FAULT once its cause is gone (docs/safety.md)");
  cmd->add_option("--aggregator", a->aggregator, "The aggregator's gRPC address, HOST:PORT")->required();
  auto* tls_opt = cmd->add_option("--tls-dir", a->tls_dir, "Mutual TLS: ca.crt and the operator's certificate (operator.crt)");
  auto* insecure = cmd->add_flag("--insecure", a->insecure, "Plaintext (an --insecure aggregator)");
  tls_opt->excludes(insecure);
  cmd->add_option("--epoch", a->epoch, "The stop_epoch to reset (default: the current one, read with GetStatus)");
  cmd->add_option("--operator", a->operator_name, "Who resets (logged by the aggregator)")->capture_default_str();
  cmd->add_option("--note", a->note, "Why (logged by the aggregator)");
  cmd->add_option("--wait-s", a->wait_s, "Retry while the cause persists or patches are not healthy long enough, s")
      ->check(CLI::Range(0.0, 600.0));
  cmd->callback([a]() {
    const service::HostPort target = service::ParseHostPort(a->aggregator, "--aggregator");
    const service::TlsConfig tls = service::LoadTls(a->tls_dir, a->insecure, "operator");
    auto stub = v1::Aggregator::NewStub(grpc::CreateChannel(target.str(), service::ChannelCredentials(tls)));
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(a->wait_s);
    for (;;) {
      std::uint64_t epoch = a->epoch >= 0 ? static_cast<std::uint64_t>(a->epoch) : 0;
      if (a->epoch < 0) {
        grpc::ClientContext ctx;
        ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(3));
        v1::AggregatorStatus status;
        const grpc::Status st = stub->GetStatus(&ctx, v1::GetStatusRequest{}, &status);
        if (!st.ok()) throw InputError("--aggregator " + target.str() + ": GetStatus failed (" + st.error_message() + ")");
        if (status.safety().state() == v1::SafetyState::STATE_CLEAR) {
          std::printf("already CLEAR (epoch %llu)\n", static_cast<unsigned long long>(status.safety().stop_epoch()));
          return;
        }
        epoch = status.safety().stop_epoch();
      }
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(3));
      v1::ResetStopRequest req;
      req.set_stop_epoch(epoch);
      req.set_operator_name(a->operator_name);
      req.set_operator_note(a->note);
      v1::ResetStopResponse resp;
      const grpc::Status st = stub->ResetStop(&ctx, req, &resp);
      if (!st.ok()) throw InputError("--aggregator " + target.str() + ": ResetStop failed (" + st.error_message() + ")");
      if (resp.accepted()) {
        std::printf("reset accepted: epoch %llu is CLEAR\n", static_cast<unsigned long long>(epoch));
        return;
      }
      const bool curable = resp.reason() == v1::RESET_REFUSAL_CAUSE_PRESENT ||
                           resp.reason() == v1::RESET_REFUSAL_NOT_HEALTHY_LONG_ENOUGH ||
                           (resp.reason() == v1::RESET_REFUSAL_WRONG_EPOCH && a->epoch < 0);
      if (!curable || std::chrono::steady_clock::now() >= deadline) {
        std::printf("reset refused (%s): %s\n", v1::ResetRefusal_Name(resp.reason()).c_str(), resp.message().c_str());
        throw CLI::RuntimeError(4);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the retry period, not a wait on a condition
    }
  });
}

}  // namespace ruffini::cli
