// Authentication and transport security of the localizer server (docs/api.md, "Authentication";
// docs/deploy.md, "Secure defaults"): the bearer token table (stored as SHA-256 digests and
// compared in constant time), a token file that is read again when it changes, the check of the
// TLS files, and the rule that decides whether a listen address is loopback. Library code: it
// reports through a callback and throws typed errors.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

namespace grpc {
class ServerCredentials;
}  // namespace grpc

namespace evloc::service {

// A SHA-256 digest.
using Sha256Digest = std::array<uint8_t, 32>;

// The SHA-256 digest of `text`.
Sha256Digest Sha256(std::string_view text);

// Bearer tokens and the maps each may use. A token file has one token per line, `TOKEN MAPS`:
// MAPS is `*` (every map) or a comma-separated list of map names (no empty names, no spaces);
// `TOKEN` may also be given as `sha256:HEX` (the 64 hex digits of the token's SHA-256), so that
// the file need not hold the secret itself. '#' starts a comment; blank lines are skipped. Only
// the digests are kept in memory; a token is found by hashing it and comparing the digest with
// every entry with CRYPTO_memcmp, so the time taken does not depend on how much of it matches.
class TokenTable {
 public:
  // Reads a token file. Throws IoError when it cannot be read, ParseError naming the file and
  // the line for a malformed line (a missing or empty map list, a duplicate token, ...).
  static TokenTable Read(const std::filesystem::path& path);
  // Parses the text of a token file; `source` names it in errors.
  static TokenTable Parse(const std::string& text, const std::string& source);
  // True when `token` is known.
  bool Knows(std::string_view token) const { return Find(token) != nullptr; }
  // True when `token` is known and may use `map_name`.
  bool Allows(std::string_view token, const std::string& map_name) const;
  // Number of tokens.
  size_t size() const { return entries_.size(); }

 private:
  // One token line.
  struct Entry {
    // SHA-256 of the token.
    Sha256Digest digest{};
    // `*`: every map.
    bool all_maps = false;
    // The maps it may use (when not all_maps).
    std::set<std::string> maps;
  };
  // The entry whose digest equals the token's, or nullptr; compares against every entry.
  const Entry* Find(std::string_view token) const;

  std::vector<Entry> entries_;
};

// A token file that is read again when it changes: each lookup first checks (at most once per
// reload interval) the file's modification time, size and inode (through symbolic links, as
// Kubernetes swaps a Secret's files), and reads it again when one differs. A file that fails to
// read or parse keeps the last good table in force and is reported through the log callback
// (once per change). Thread-safe.
class TokenFile {
 public:
  // A report line (no trailing newline).
  using LogFunction = std::function<void(const std::string& line)>;

  // Reads `path` now (throws like TokenTable::Read). `reload_interval`: the least time between
  // two checks of the file; zero checks on every lookup.
  TokenFile(std::filesystem::path path, std::chrono::milliseconds reload_interval,
            LogFunction log = {});

  // The table in force (after reading the file again if it changed).
  std::shared_ptr<const TokenTable> Current();
  // True when `token` is known (TokenTable::Knows on the current table).
  bool Knows(std::string_view token) { return Current()->Knows(token); }
  // True when `token` may use `map_name` (TokenTable::Allows on the current table).
  bool Allows(std::string_view token, const std::string& map_name) {
    return Current()->Allows(token, map_name);
  }
  // Number of times the file was read again successfully after it changed.
  int64_t reloads() const;

 private:
  // What identifies a version of the file.
  struct Stamp {
    int64_t mtime_ns = 0;
    int64_t size = -1;
    uint64_t inode = 0;
    bool operator==(const Stamp& other) const {
      return mtime_ns == other.mtime_ns && size == other.size && inode == other.inode;
    }
  };
  // The file's stamp; nullopt when it cannot be stat'ed.
  std::optional<Stamp> StampOf() const;

  const std::filesystem::path path_;
  const std::chrono::milliseconds reload_interval_;
  const LogFunction log_;
  mutable std::mutex mutex_;
  std::shared_ptr<const TokenTable> table_;
  // The stamp of the version last read (good or not), and when the file was last checked.
  std::optional<Stamp> stamp_;
  std::chrono::steady_clock::time_point last_check_;
  int64_t reloads_ = 0;
};

// Checks the server's TLS files before the server starts: the certificate chain and the private
// key are readable PEM and belong together, and the client CA (when given) holds at least one
// certificate. Throws IoError for an unreadable file, InvalidArgumentError naming the file (and
// the flag) for a malformed one.
void CheckTlsFiles(const std::filesystem::path& cert_file, const std::filesystem::path& key_file,
                   const std::optional<std::filesystem::path>& client_ca_file);

// The server credentials: plaintext without `cert_file`; else TLS with the certificate chain and
// key read from the files and read again when they change (checked every `reload_interval_s`
// seconds; gRPC's FileWatcherCertificateProvider), and with `client_ca_file` mutual TLS: every
// client must present a certificate signed by that CA (also read again when it changes). Checks
// the files first (CheckTlsFiles).
std::shared_ptr<grpc::ServerCredentials> MakeServerCredentials(
    const std::optional<std::filesystem::path>& cert_file,
    const std::optional<std::filesystem::path>& key_file,
    const std::optional<std::filesystem::path>& client_ca_file, int reload_interval_s);

// What protects a listening server.
struct ListenSecurity {
  // TLS is on (--tls-cert, --tls-key).
  bool tls = false;
  // Clients need a bearer token (--auth-tokens).
  bool tokens = false;
  // Clients need a certificate of the client CA (--tls-client-ca).
  bool client_certificates = false;
  // The operator accepts an open server on a network address (--insecure).
  bool insecure = false;
};

// Refuses an open server on a network address: unless `address` is loopback
// (IsLoopbackListenAddress) or `security.insecure`, it needs TLS and authentication (tokens or
// client certificates). Throws InvalidArgumentError saying what is missing, why, and what to do.
void CheckListenSecurity(const std::string& address, const ListenSecurity& security);

// One line for the effective configuration, e.g. "TLS, bearer tokens" or "INSECURE: ...".
std::string DescribeListenSecurity(const std::string& address, const ListenSecurity& security);

// True when a gRPC listen address reaches this machine only: an IPv4 address in 127.0.0.0/8,
// [::1], `localhost`, or a Unix domain socket (unix:..., unix-abstract:...). Anything else,
// including 0.0.0.0, [::], an empty host and a host name, is not loopback.
bool IsLoopbackListenAddress(const std::string& address);

}  // namespace evloc::service
