// ruffini reset: the operator's ResetStop. A reset acts only on the stop it names (docs/safety.md): the
// aggregator run and the stop_epoch are read ONCE with GetStatus (what the operator is looking at), or given
// with --epoch and --run-id, and the request names both. A refusal is final, except that with --wait-s the
// tool retries RESET_REFUSAL_NOT_HEALTHY_LONG_ENOUGH for that same run and epoch (the patches must stay
// healthy a while: time cures it), saying what it waits for. It never moves on to another epoch: a
// WRONG_EPOCH or WRONG_RUN refusal means a new stop (or a restart) the operator has not seen, and the tool
// says which state the aggregator is in now. CAUSE_PRESENT is not retried either: the operator removes the
// cause, then resets.
// Exit codes: 0 accepted (or already CLEAR), 4 refused (the message says why), 1 bad input or no aggregator.
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cinttypes>
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

namespace {

std::string RunText(std::uint64_t run_id) {
  char buf[24];
  std::snprintf(buf, sizeof buf, "0x%016" PRIx64, run_id);
  return buf;
}

std::string StateText(const v1::SafetyState& s) {
  std::string text = v1::SafetyState::State_Name(s.state());
  if (text.rfind("STATE_", 0) == 0) text = text.substr(6);
  text += " epoch " + std::to_string(s.stop_epoch());
  if (s.state() != v1::SafetyState::STATE_CLEAR && s.has_cause()) {
    text += " cause " + v1::SafetyCause::Kind_Name(s.cause().kind());
    if (!s.cause().patch_id().empty()) text += " " + s.cause().patch_id();
  }
  return text;
}

v1::AggregatorStatus GetStatus(v1::Aggregator::Stub& stub, const std::string& target) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(3));
  v1::AggregatorStatus status;
  const grpc::Status st = stub.GetStatus(&ctx, v1::GetStatusRequest{}, &status);
  if (!st.ok()) throw InputError("--aggregator " + target + ": GetStatus failed (" + st.error_message() + ")");
  return status;
}

}  // namespace

void RegisterResetCommand(CLI::App& app) {
  struct Args {
    std::string aggregator, tls_dir, operator_name = "ruffini reset", note, run_id;
    bool insecure = false;
    long long epoch = -1;
    double wait_s = 0;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "reset", "The operator's ResetStop: clear the latched STOP or FAULT you saw, once its cause is gone (docs/safety.md)");
  cmd->add_option("--aggregator", a->aggregator, "The aggregator's gRPC address, HOST:PORT")->required();
  auto* tls_opt = cmd->add_option("--tls-dir", a->tls_dir, "Mutual TLS: ca.crt and the operator's certificate (operator.crt)");
  auto* insecure = cmd->add_flag("--insecure", a->insecure, "Plaintext (an --insecure aggregator)");
  tls_opt->excludes(insecure);
  auto* epoch_opt = cmd->add_option("--epoch", a->epoch,
                                    "The stop_epoch to reset, as seen (with --run-id; default: both read once with GetStatus)");
  auto* run_opt = cmd->add_option("--run-id", a->run_id,
                                  "The aggregator run of that epoch (SafetyState.aggregator_run_id, e.g. 0x1f2e...; with --epoch)");
  epoch_opt->needs(run_opt);
  run_opt->needs(epoch_opt);
  cmd->add_option("--operator", a->operator_name, "Who resets (logged by the aggregator)")->capture_default_str();
  cmd->add_option("--note", a->note, "Why (logged by the aggregator)");
  cmd->add_option("--wait-s", a->wait_s,
                  "Retry, for the same run and epoch, while the aggregator answers that the patches have not been "
                  "healthy long enough, s (no other refusal is retried)")
      ->check(CLI::Range(0.0, 600.0));
  cmd->callback([a]() {
    const service::HostPort target = service::ParseHostPort(a->aggregator, "--aggregator");
    const service::TlsConfig tls = service::LoadTls(a->tls_dir, a->insecure, "operator");
    auto stub = v1::Aggregator::NewStub(grpc::CreateChannel(target.str(), service::ChannelCredentials(tls)));

    // The stop this reset is for, fixed once.
    std::uint64_t epoch = 0, run_id = 0;
    if (a->epoch >= 0) {
      epoch = static_cast<std::uint64_t>(a->epoch);
      try {
        std::size_t used = 0;
        run_id = std::stoull(a->run_id, &used, 0);
        if (used != a->run_id.size()) throw std::invalid_argument("trailing characters");
      } catch (const std::exception&) {
        throw InputError("--run-id " + a->run_id + ": not a number (decimal, or hexadecimal with 0x)");
      }
    } else {
      const v1::AggregatorStatus status = GetStatus(*stub, target.str());
      if (status.safety().state() == v1::SafetyState::STATE_CLEAR) {
        std::printf("already CLEAR (epoch %llu, run %s)\n", static_cast<unsigned long long>(status.safety().stop_epoch()),
                    RunText(status.aggregator_run_id()).c_str());
        return;
      }
      epoch = status.safety().stop_epoch();
      // The run of the state the operator sees (the status names it too).
      run_id = status.safety().aggregator_run_id() != 0 ? status.safety().aggregator_run_id() : status.aggregator_run_id();
      std::printf("resetting %s (run %s)\n", StateText(status.safety()).c_str(), RunText(run_id).c_str());
    }
    std::fflush(stdout);

    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(a->wait_s);
    std::string last_wait;
    for (;;) {
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(3));
      v1::ResetStopRequest req;
      req.set_aggregator_run_id(run_id);
      req.set_stop_epoch(epoch);
      req.set_operator_name(a->operator_name);
      req.set_operator_note(a->note);
      v1::ResetStopResponse resp;
      const grpc::Status st = stub->ResetStop(&ctx, req, &resp);
      if (!st.ok()) throw InputError("--aggregator " + target.str() + ": ResetStop failed (" + st.error_message() + ")");
      if (resp.accepted()) {
        std::printf("reset accepted: epoch %llu of run %s is CLEAR\n", static_cast<unsigned long long>(epoch),
                    RunText(run_id).c_str());
        return;
      }
      if (resp.reason() == v1::RESET_REFUSAL_NOT_HEALTHY_LONG_ENOUGH && std::chrono::steady_clock::now() < deadline) {
        if (resp.message() != last_wait) {  // say what it waits for, once per change
          std::printf("waiting (epoch %llu of run %s): %s\n", static_cast<unsigned long long>(epoch),
                      RunText(run_id).c_str(), resp.message().c_str());
          std::fflush(stdout);
          last_wait = resp.message();
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the retry period, not a wait on a condition
        continue;
      }
      std::printf("reset refused (%s): %s\n", v1::ResetRefusal_Name(resp.reason()).c_str(), resp.message().c_str());
      if (resp.reason() == v1::RESET_REFUSAL_WRONG_EPOCH || resp.reason() == v1::RESET_REFUSAL_WRONG_RUN) {
        // Name what the aggregator is in now, for the operator to look at; never reset it unseen.
        try {
          const v1::AggregatorStatus now = GetStatus(*stub, target.str());
          std::printf("the aggregator is now at %s (run %s), not epoch %llu of run %s: look at it, then reset it by "
                      "name if you mean to\n",
                      StateText(now.safety()).c_str(), RunText(now.aggregator_run_id()).c_str(),
                      static_cast<unsigned long long>(epoch), RunText(run_id).c_str());
        } catch (const InputError&) {
        }
      }
      throw CLI::RuntimeError(4);
    }
  });
}

}  // namespace ruffini::cli
