#pragma once
// Mutual TLS for every gRPC link, and who a caller is (docs/security.md).
//
// A service gets exactly one of `--tls-dir DIR` (mutual TLS) or `--insecure` (plaintext, logged as a warning).
// DIR holds, as deploy/tls/make-dev-ca.sh writes them: ca.crt (the CA every peer must chain to) and the
// service's own NAME.crt / NAME.key, NAME being `aggregator`, `controller`, `operator` or `decoder-PATCH`.
// Identities are SPIFFE IDs in the certificate's URI SAN: spiffe://ruffini/decoder/PATCH,
// spiffe://ruffini/controller, spiffe://ruffini/operator (and spiffe://ruffini/aggregator for the server).
#include <grpcpp/security/credentials.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/server_context.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

namespace ruffini::service {

struct TlsConfig {
  bool insecure = true;
  std::string dir, name;                 // where and which files (empty when insecure)
  std::string ca_pem, cert_pem, key_pem;
};

// Exactly one of tls_dir (not empty) and insecure. Reads DIR/ca.crt, DIR/NAME.crt and DIR/NAME.key (or, when
// DIR has no NAME.crt, DIR/tls.crt and DIR/tls.key: a Kubernetes TLS Secret mounted as a folder); throws
// InputError naming the flag or the file that is missing or unreadable.
TlsConfig LoadTls(const std::string& tls_dir, bool insecure, const std::string& name);
// Logs what the service will do: info for mutual TLS, a warning (with what it means) for plaintext.
void LogTls(const TlsConfig& tls, std::string_view what_insecure_means);

// Server: requires and verifies a client certificate against ca.crt. Plaintext when insecure.
std::shared_ptr<grpc::ServerCredentials> ServerCredentials(const TlsConfig& tls);
// Client: verifies the server against ca.crt and presents NAME.crt. Plaintext when insecure.
std::shared_ptr<grpc::ChannelCredentials> ChannelCredentials(const TlsConfig& tls);

enum class Role : std::uint8_t { kNone, kDecoder, kController, kOperator, kAny };
std::string_view RoleName(Role r) noexcept;
struct Identity {
  Role role = Role::kNone;
  std::string patch;   // kDecoder: the patch it may publish
  std::string id;      // the SPIFFE ID ("" when the peer had none, "insecure" on a plaintext server)
};
// "spiffe://ruffini/controller" -> kController; "spiffe://ruffini/decoder/forearm_a" -> kDecoder, "forearm_a";
// anything else -> kNone.
Identity ParseIdentity(std::string_view spiffe_id);
// The caller of an RPC, from its verified client certificate (the auth context's peer_spiffe_id). A plaintext
// server (insecure) treats every caller as every role: kAny.
Identity CallerIdentity(const grpc::ServerContextBase& ctx, bool insecure);

// TLS handshakes refused by this process's gRPC (it reports them only in its log: this hooks gRPC's log
// function, forwards every line to stderr and counts "Handshake failed"). Call once, first thing in main.
struct HandshakeRefusals {
  std::atomic<std::uint64_t> no_certificate{0};   // the client sent no certificate
  std::atomic<std::uint64_t> bad_certificate{0};  // unknown CA, expired, wrong usage, ...
  std::atomic<std::uint64_t> other{0};            // any other handshake failure
};
void CountHandshakeRefusals();
const HandshakeRefusals& handshake_refusals() noexcept;

}  // namespace ruffini::service
