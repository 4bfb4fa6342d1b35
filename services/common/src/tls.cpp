#include "ruffini/service/tls.h"

#include <filesystem>

#include <grpc/grpc_security_constants.h>
#include <grpc/support/log.h>
#include <grpcpp/security/auth_context.h>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <fstream>
#include <sstream>

#include "ruffini/error.h"

namespace ruffini::service {

namespace {

std::string ReadPem(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  if (!in || !(text << in.rdbuf())) throw InputError("--tls-dir: cannot read " + path);
  if (text.str().find("-----BEGIN ") == std::string::npos) throw InputError("--tls-dir: " + path + " is not PEM");
  return text.str();
}

HandshakeRefusals g_refusals;

void LogAndCount(gpr_log_func_args* a) {
  const std::string_view msg = a->message ? a->message : "";
  if (msg.find("Handshake failed") != std::string_view::npos) {
    if (msg.find("did not return a certificate") != std::string_view::npos) {
      g_refusals.no_certificate.fetch_add(1, std::memory_order_relaxed);
    } else if (msg.find("certificate verify failed") != std::string_view::npos ||
               msg.find("certificate") != std::string_view::npos) {
      g_refusals.bad_certificate.fetch_add(1, std::memory_order_relaxed);
    } else {
      g_refusals.other.fetch_add(1, std::memory_order_relaxed);
    }
  }
  std::fprintf(stderr, "grpc %s %s:%d] %.*s\n", gpr_log_severity_string(a->severity), a->file ? a->file : "?",
               a->line, static_cast<int>(msg.size()), msg.data());
}

}  // namespace

TlsConfig LoadTls(const std::string& tls_dir, bool insecure, const std::string& name) {
  if (insecure == !tls_dir.empty()) throw InputError("give exactly one of --tls-dir DIR (mutual TLS) and --insecure");
  TlsConfig t;
  if (insecure) return t;
  t.insecure = false;
  t.dir = tls_dir;
  t.name = name;
  t.ca_pem = ReadPem(tls_dir + "/ca.crt");
  // NAME.crt / NAME.key (make-dev-ca.sh's folder of every certificate), else tls.crt / tls.key (a Kubernetes
  // TLS Secret mounted for one service).
  const bool own = std::filesystem::exists(tls_dir + "/" + name + ".crt") ||
                   !std::filesystem::exists(tls_dir + "/tls.crt");
  t.name = own ? name : "tls";
  t.cert_pem = ReadPem(tls_dir + "/" + t.name + ".crt");
  t.key_pem = ReadPem(tls_dir + "/" + t.name + ".key");
  return t;
}

void LogTls(const TlsConfig& tls, std::string_view what_insecure_means) {
  if (tls.insecure) {
    spdlog::warn("--insecure: PLAINTEXT gRPC, no TLS and no identities; {}", what_insecure_means);
  } else {
    spdlog::info("mutual TLS: CA {}/ca.crt, own certificate {}/{}.crt", tls.dir, tls.dir, tls.name);
  }
}

std::shared_ptr<grpc::ServerCredentials> ServerCredentials(const TlsConfig& tls) {
  if (tls.insecure) return grpc::InsecureServerCredentials();
  grpc::SslServerCredentialsOptions o(GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  o.pem_root_certs = tls.ca_pem;
  o.pem_key_cert_pairs.push_back({tls.key_pem, tls.cert_pem});
  return grpc::SslServerCredentials(o);
}

std::shared_ptr<grpc::ChannelCredentials> ChannelCredentials(const TlsConfig& tls) {
  if (tls.insecure) return grpc::InsecureChannelCredentials();
  grpc::SslCredentialsOptions o;
  o.pem_root_certs = tls.ca_pem;
  o.pem_private_key = tls.key_pem;
  o.pem_cert_chain = tls.cert_pem;
  return grpc::SslCredentials(o);
}

std::string_view RoleName(Role r) noexcept {
  switch (r) {
    case Role::kNone: return "none";
    case Role::kDecoder: return "decoder";
    case Role::kController: return "controller";
    case Role::kOperator: return "operator";
    case Role::kAny: return "any (insecure)";
  }
  return "none";
}

Identity ParseIdentity(std::string_view id) {
  Identity out;
  out.id = std::string(id);
  constexpr std::string_view kPrefix = "spiffe://ruffini/";
  if (id.substr(0, kPrefix.size()) != kPrefix) return out;
  const std::string_view rest = id.substr(kPrefix.size());
  constexpr std::string_view kDecoder = "decoder/";
  if (rest == "controller") {
    out.role = Role::kController;
  } else if (rest == "operator") {
    out.role = Role::kOperator;
  } else if (rest.substr(0, kDecoder.size()) == kDecoder && rest.size() > kDecoder.size() &&
             rest.find('/', kDecoder.size()) == std::string_view::npos) {
    out.role = Role::kDecoder;
    out.patch = std::string(rest.substr(kDecoder.size()));
  }
  return out;
}

Identity CallerIdentity(const grpc::ServerContextBase& ctx, bool insecure) {
  if (insecure) return Identity{Role::kAny, "", "insecure"};
  const auto auth = ctx.auth_context();
  if (!auth) return Identity{};
  const auto ids = auth->FindPropertyValues(GRPC_PEER_SPIFFE_ID_PROPERTY_NAME);
  if (ids.size() != 1) return Identity{};
  return ParseIdentity(std::string_view(ids.front().data(), ids.front().size()));
}

void CountHandshakeRefusals() { gpr_set_log_function(LogAndCount); }

const HandshakeRefusals& handshake_refusals() noexcept { return g_refusals; }

}  // namespace ruffini::service
