// Authentication and transport security of the localizer server (docs/api.md, "Authentication";
// docs/deploy.md, "Secure defaults"): the bearer token table (stored as SHA-256 digests and
// compared in constant time), a token file that is read again when it changes, the check of the
// TLS files, and the rule that decides whether a listen address is loopback. Library code: it
// reports through a callback and throws typed errors.
#pragma once

#include <array>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "core/common/file_util.h"
#include "core/common/log.h"

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
  // A report line (no trailing newline) and its level (info: read again; warning: the file is
  // missing or invalid and the previous tokens stay in force).
  using LogFunction = std::function<void(LogLevel level, const std::string& line)>;

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

// The server's TLS material as PEM text.
struct TlsPem {
  // Certificate chain.
  std::string cert;
  // Private key.
  std::string key;
  // Client CA certificate(s); empty without mutual TLS.
  std::string client_ca;
  bool operator==(const TlsPem& other) const {
    return cert == other.cert && key == other.key && client_ca == other.client_ca;
  }
};

// Reads the server's TLS files and checks them: the certificate chain and the private key are
// PEM and belong together, and the client CA (when given) holds a certificate. Throws IoError
// for an unreadable file, InvalidArgumentError naming the file (and its flag) for a bad one.
TlsPem ReadTlsFiles(const std::filesystem::path& cert_file, const std::filesystem::path& key_file,
                    const std::optional<std::filesystem::path>& client_ca_file);

// The server's TLS credentials, read again when the files change, without a restart. gRPC 1.51's
// FileWatcherCertificateProvider alone installs whatever it reads: while a certificate is
// half-written, or a key and certificate are replaced one after the other (a key that does not
// belong to the certificate), every new handshake fails (SecureServerTest shows it). So the
// operator's files are not given to gRPC directly: this object checks them (ReadTlsFiles) every
// `reload_interval_s` seconds on its own thread and publishes only a valid, matching set into a
// private folder (mode 0700 under the temporary directory, $TMPDIR or /tmp), one generation
// folder per version behind a symbolic link that is swapped atomically; gRPC's provider watches
// that folder. A set that is not valid is logged (once per problem) and the previous certificate
// stays in force. With a client CA, every client must present a certificate signed by it
// (mutual TLS).
class ServerTlsFiles {
 public:
  // A report line (no trailing newline) and its level (info: new files in force; warning: they
  // are not valid); called from the watcher thread.
  using LogFunction = std::function<void(LogLevel level, const std::string& line)>;

  // Reads and checks the files (throws like ReadTlsFiles), publishes them and starts watching.
  // Throws IoError when the private folder cannot be made.
  ServerTlsFiles(std::filesystem::path cert_file, std::filesystem::path key_file,
                 std::optional<std::filesystem::path> client_ca_file, int reload_interval_s,
                 LogFunction log = {});
  // Stops watching and removes the private folder.
  ~ServerTlsFiles();
  ServerTlsFiles(const ServerTlsFiles&) = delete;
  ServerTlsFiles& operator=(const ServerTlsFiles&) = delete;

  // The credentials to listen with.
  std::shared_ptr<grpc::ServerCredentials> credentials() const { return credentials_; }
  // Number of new versions published after the first.
  int64_t reloads() const;

 private:
  // Writes `pem` as a new generation and points the link at it; drops generations older than
  // the previous one (gRPC may still be reading that).
  void Publish(const TlsPem& pem);
  // Until stopped: checks the files every interval and publishes a changed, valid set.
  void WatchLoop();

  const std::filesystem::path cert_file_;
  const std::filesystem::path key_file_;
  const std::optional<std::filesystem::path> client_ca_file_;
  const std::chrono::seconds interval_;
  const LogFunction log_;
  std::unique_ptr<PrivateTempFolder> folder_;
  int64_t generation_ = 0;
  TlsPem published_;
  std::shared_ptr<grpc::ServerCredentials> credentials_;
  mutable std::mutex mutex_;
  std::condition_variable stop_cv_;
  bool stop_ = false;
  int64_t reloads_ = 0;
  std::thread watcher_;
};

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
