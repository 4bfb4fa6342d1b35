// Who may call what: the caller's role from its TLS identity (docs/security.md); refusals counted and logged.
#include <spdlog/spdlog.h>

#include "server_impl.h"

namespace ruffini::aggregator {

grpc::Status Denied(std::string_view rpc) {
  return grpc::Status(grpc::StatusCode::PERMISSION_DENIED,
                      "this caller's identity (its TLS client certificate) may not call " + std::string(rpc));
}

bool AggregatorServer::Impl::Allowed(const grpc::CallbackServerContext* ctx, std::string_view rpc,
                                     std::initializer_list<service::Role> allowed, service::Identity* who) {
  service::Identity id = service::CallerIdentity(*ctx, config.tls.insecure);
  bool ok = id.role == service::Role::kAny;
  for (auto r : allowed) ok = ok || id.role == r;
  if (!ok) {
    stats.auth_wrong_role.fetch_add(1);
    spdlog::warn("{} refused (PERMISSION_DENIED) for {} '{}' from {}", rpc, service::RoleName(id.role), id.id,
                 ctx->peer());
  }
  if (who) *who = std::move(id);
  return ok;
}

}  // namespace ruffini::aggregator
