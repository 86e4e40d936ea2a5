#include "localizer/service/auth.h"

#include <algorithm>
#include <cctype>
#include <fstream>
#include <map>
#include <sstream>

#include <arpa/inet.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/security/tls_certificate_provider.h>
#include <grpcpp/security/tls_credentials_options.h>
#include <netinet/in.h>
#include <openssl/bio.h>
#include <openssl/crypto.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <sys/stat.h>

#include "core/common/error.h"
#include "core/common/file_util.h"

namespace evloc::service {
namespace {

std::string Trim(const std::string& text) {
  const size_t begin = text.find_first_not_of(" \t\r");
  if (begin == std::string::npos) return "";
  const size_t end = text.find_last_not_of(" \t\r");
  return text.substr(begin, end - begin + 1);
}

// Parses `sha256:HEX` (64 hex digits); false when `text` is not of that form.
bool ParseDigest(const std::string& text, Sha256Digest* digest) {
  static constexpr std::string_view kPrefix = "sha256:";
  if (text.size() != kPrefix.size() + 64 || text.compare(0, kPrefix.size(), kPrefix) != 0) {
    return false;
  }
  for (size_t i = 0; i < digest->size(); ++i) {
    const std::string pair = text.substr(kPrefix.size() + 2 * i, 2);
    if (!std::isxdigit(static_cast<unsigned char>(pair[0])) ||
        !std::isxdigit(static_cast<unsigned char>(pair[1]))) {
      return false;
    }
    (*digest)[i] = static_cast<uint8_t>(std::stoi(pair, nullptr, 16));
  }
  return true;
}

// Frees OpenSSL objects.
struct BioFree {
  void operator()(BIO* bio) const { BIO_free(bio); }
};
struct X509Free {
  void operator()(X509* certificate) const { X509_free(certificate); }
};
struct KeyFree {
  void operator()(EVP_PKEY* key) const { EVP_PKEY_free(key); }
};

// A memory BIO over `pem` (which must outlive it).
std::unique_ptr<BIO, BioFree> MemoryBio(const std::string& pem) {
  return std::unique_ptr<BIO, BioFree>(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
}

}  // namespace

Sha256Digest Sha256(std::string_view text) {
  Sha256Digest digest{};
  unsigned int length = 0;
  if (EVP_Digest(text.data(), text.size(), digest.data(), &length, EVP_sha256(), nullptr) != 1 ||
      length != digest.size()) {
    throw Error("OpenSSL could not compute a SHA-256 digest (libcrypto without SHA-256?)");
  }
  return digest;
}

// ---------------------------------------------------------------------------------------------
// TokenTable.

TokenTable TokenTable::Read(const std::filesystem::path& path) {
  std::string text;
  try {
    text = ReadFileToString(path);
  } catch (const IoError&) {
    throw IoError("cannot read the token file '" + path.string() +
                  "' (check the path given to --auth-tokens and that the server may read it)");
  }
  return Parse(text, path.string());
}

TokenTable TokenTable::Parse(const std::string& text, const std::string& source) {
  static const std::string kFormat =
      " (a line is `TOKEN *` for every map or `TOKEN map1,map2`; docs/api.md, \"Authentication\")";
  TokenTable table;
  // Digest -> line where it was first given.
  std::map<Sha256Digest, int64_t> lines;
  std::istringstream input(text);
  std::string line;
  int64_t line_number = 0;
  while (std::getline(input, line)) {
    ++line_number;
    const size_t comment = line.find('#');
    if (comment != std::string::npos) line.resize(comment);
    line = Trim(line);
    if (line.empty()) continue;
    std::istringstream fields(line);
    std::string token;
    std::string maps;
    std::string extra;
    fields >> token >> maps >> extra;
    // The messages never repeat the token: they end up in logs.
    if (!extra.empty()) {
      throw ParseError::AtLine(source, line_number,
                               "more than two fields: map names are separated by commas, "
                               "without spaces" +
                                   kFormat);
    }
    if (maps.empty()) {
      throw ParseError::AtLine(source, line_number,
                               "the token has no map list: write `*` after it to allow every "
                               "map, or the names of the maps it may use" +
                                   kFormat);
    }
    Entry entry;
    if (token.rfind("sha256:", 0) == 0) {
      if (!ParseDigest(token, &entry.digest)) {
        throw ParseError::AtLine(source, line_number,
                                 "a `sha256:` token must be followed by exactly 64 hex digits "
                                 "(the output of `printf %s TOKEN | sha256sum`)");
      }
    } else {
      entry.digest = Sha256(token);
    }
    if (maps == "*") {
      entry.all_maps = true;
    } else {
      std::string name;
      std::istringstream names(maps);
      size_t count = 0;
      while (std::getline(names, name, ',')) {
        ++count;
        if (name.empty()) {
          throw ParseError::AtLine(source, line_number,
                                   "an empty map name in the list '" + maps +
                                       "' (a lone, leading, trailing or doubled comma)" + kFormat);
        }
        if (name.find('*') != std::string::npos) {
          throw ParseError::AtLine(source, line_number,
                                   "`*` (every map) must stand alone, not in a list" + kFormat);
        }
        entry.maps.insert(name);
      }
      // getline does not report an empty field after a trailing comma.
      if (count == 0 || maps.back() == ',') {
        throw ParseError::AtLine(source, line_number,
                                 "an empty map name in the list '" + maps +
                                     "' (a lone, leading, trailing or doubled comma)" + kFormat);
      }
    }
    const auto [first, inserted] = lines.emplace(entry.digest, line_number);
    if (!inserted) {
      throw ParseError::AtLine(source, line_number,
                               "the token of line " + std::to_string(first->second) +
                                   " is listed again (one line per token)");
    }
    table.entries_.push_back(std::move(entry));
  }
  return table;
}

const TokenTable::Entry* TokenTable::Find(std::string_view token) const {
  const Sha256Digest digest = Sha256(token);
  const Entry* found = nullptr;
  // Every entry is compared, in constant time each: no early exit on a match.
  for (const Entry& entry : entries_) {
    const bool equal = CRYPTO_memcmp(entry.digest.data(), digest.data(), digest.size()) == 0;
    if (equal && found == nullptr) found = &entry;
  }
  return found;
}

bool TokenTable::Allows(std::string_view token, const std::string& map_name) const {
  const Entry* entry = Find(token);
  if (entry == nullptr) return false;
  return entry->all_maps || entry->maps.count(map_name) > 0;
}

// ---------------------------------------------------------------------------------------------
// TokenFile.

TokenFile::TokenFile(std::filesystem::path path, std::chrono::milliseconds reload_interval,
                     LogFunction log)
    : path_(std::move(path)), reload_interval_(reload_interval), log_(std::move(log)) {
  stamp_ = StampOf();
  table_ = std::make_shared<const TokenTable>(TokenTable::Read(path_));
  last_check_ = std::chrono::steady_clock::now();
}

std::optional<TokenFile::Stamp> TokenFile::StampOf() const {
  struct stat status {};
  if (::stat(path_.c_str(), &status) != 0) return std::nullopt;
  Stamp stamp;
  stamp.mtime_ns = static_cast<int64_t>(status.st_mtim.tv_sec) * 1'000'000'000 +
                   static_cast<int64_t>(status.st_mtim.tv_nsec);
  stamp.size = static_cast<int64_t>(status.st_size);
  stamp.inode = static_cast<uint64_t>(status.st_ino);
  return stamp;
}

std::shared_ptr<const TokenTable> TokenFile::Current() {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto now = std::chrono::steady_clock::now();
  if (now - last_check_ < reload_interval_) return table_;
  last_check_ = now;
  const std::optional<Stamp> stamp = StampOf();
  if (stamp == stamp_) return table_;
  stamp_ = stamp;
  const std::string kept =
      "; the " + std::to_string(table_->size()) + " tokens read before stay in force";
  if (!stamp) {
    if (log_) {
      log_(LogLevel::kWarning,
           "token file '" + path_.string() + "' cannot be found or read" + kept);
    }
    return table_;
  }
  try {
    table_ = std::make_shared<const TokenTable>(TokenTable::Read(path_));
    ++reloads_;
    if (log_) {
      log_(LogLevel::kInfo, "token file '" + path_.string() + "' changed: read again, " +
                                std::to_string(table_->size()) + " tokens");
    }
  } catch (const std::exception& error) {
    if (log_) {
      log_(LogLevel::kWarning,
           std::string("token file changed but is not valid: ") + error.what() + kept);
    }
  }
  return table_;
}

int64_t TokenFile::reloads() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return reloads_;
}

// ---------------------------------------------------------------------------------------------
// TLS files and listen addresses.

TlsPem ReadTlsFiles(const std::filesystem::path& cert_file, const std::filesystem::path& key_file,
                    const std::optional<std::filesystem::path>& client_ca_file) {
  // OpenSSL keeps failures in a per-thread queue, and with an old failure queued the PEM readers
  // of OpenSSL 3.0 fail on valid input too: start (and end, below) with an empty queue.
  ERR_clear_error();
  struct ClearErrors {
    ~ClearErrors() { ERR_clear_error(); }
  } clear_errors;
  TlsPem pem;
  pem.cert = ReadFileToString(cert_file);
  pem.key = ReadFileToString(key_file);
  const std::unique_ptr<X509, X509Free> certificate(
      PEM_read_bio_X509(MemoryBio(pem.cert).get(), nullptr, nullptr, nullptr));
  if (!certificate) {
    throw InvalidArgumentError("--tls-cert: '" + cert_file.string() +
                               "' holds no PEM certificate (expected -----BEGIN CERTIFICATE-----)");
  }
  const std::unique_ptr<EVP_PKEY, KeyFree> key(
      PEM_read_bio_PrivateKey(MemoryBio(pem.key).get(), nullptr, nullptr, nullptr));
  if (!key) {
    throw InvalidArgumentError("--tls-key: '" + key_file.string() +
                               "' holds no unencrypted PEM private key");
  }
  if (X509_check_private_key(certificate.get(), key.get()) != 1) {
    throw InvalidArgumentError("--tls-key: the key in '" + key_file.string() +
                               "' does not belong to the certificate in '" + cert_file.string() +
                               "' (give the pair the certificate was issued for)");
  }
  if (client_ca_file) {
    pem.client_ca = ReadFileToString(*client_ca_file);
    const std::unique_ptr<X509, X509Free> ca(
        PEM_read_bio_X509(MemoryBio(pem.client_ca).get(), nullptr, nullptr, nullptr));
    if (!ca) {
      throw InvalidArgumentError("--tls-client-ca: '" + client_ca_file->string() +
                                 "' holds no PEM certificate (the CA that issues client "
                                 "certificates)");
    }
  }
  return pem;
}

// ---------------------------------------------------------------------------------------------
// ServerTlsFiles.

namespace {

constexpr char kCurrent[] = "current";

// Writes `content` to `path`, readable by the owner only.
void WritePrivateFile(const std::filesystem::path& path, const std::string& content) {
  {
    std::ofstream file(path, std::ios::binary | std::ios::trunc);
    file << content;
    file.close();
    if (!file) throw IoError("cannot write '" + path.string() + "' (the TLS files' private copy)");
  }
  std::filesystem::permissions(
      path, std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
}

}  // namespace

ServerTlsFiles::ServerTlsFiles(std::filesystem::path cert_file, std::filesystem::path key_file,
                               std::optional<std::filesystem::path> client_ca_file,
                               int reload_interval_s, LogFunction log)
    : cert_file_(std::move(cert_file)),
      key_file_(std::move(key_file)),
      client_ca_file_(std::move(client_ca_file)),
      interval_(std::max(1, reload_interval_s)),
      log_(std::move(log)) {
  published_ = ReadTlsFiles(cert_file_, key_file_, client_ca_file_);
  folder_ = std::make_unique<PrivateTempFolder>("evloc-tls", "the TLS files");
  Publish(published_);  // On error, the folder goes with the half-built object.
  const std::filesystem::path current = folder_->path() / kCurrent;
  const auto interval = static_cast<unsigned int>(interval_.count());
  auto provider =
      client_ca_file_
          ? std::make_shared<grpc::experimental::FileWatcherCertificateProvider>(
                (current / "tls.key").string(), (current / "tls.crt").string(),
                (current / "ca.crt").string(), interval)
          : std::make_shared<grpc::experimental::FileWatcherCertificateProvider>(
                (current / "tls.key").string(), (current / "tls.crt").string(), interval);
  grpc::experimental::TlsServerCredentialsOptions options(provider);
  options.watch_identity_key_cert_pairs();
  if (client_ca_file_) {
    options.watch_root_certs();
    options.set_cert_request_type(GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  } else {
    options.set_cert_request_type(GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE);
  }
  credentials_ = grpc::experimental::TlsServerCredentials(options);
  watcher_ = std::thread([this] { WatchLoop(); });
}

ServerTlsFiles::~ServerTlsFiles() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  stop_cv_.notify_all();
  watcher_.join();
  credentials_.reset();
}

int64_t ServerTlsFiles::reloads() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return reloads_;
}

void ServerTlsFiles::Publish(const TlsPem& pem) {
  ++generation_;
  const std::string name = "gen-" + std::to_string(generation_);
  const std::filesystem::path generation = folder_->path() / name;
  std::filesystem::create_directory(generation);
  WritePrivateFile(generation / "tls.crt", pem.cert);
  WritePrivateFile(generation / "tls.key", pem.key);
  if (client_ca_file_) WritePrivateFile(generation / "ca.crt", pem.client_ca);
  // Swap the link atomically: a new link under a temporary name renamed over the old one.
  const std::filesystem::path link = folder_->path() / (std::string(kCurrent) + ".new");
  std::error_code ignored;
  std::filesystem::remove(link, ignored);
  std::filesystem::create_directory_symlink(name, link);
  std::filesystem::rename(link, folder_->path() / kCurrent);
  if (generation_ > 2) {
    std::filesystem::remove_all(folder_->path() / ("gen-" + std::to_string(generation_ - 2)),
                                ignored);
  }
}

void ServerTlsFiles::WatchLoop() {
  std::optional<std::string> last_error;
  std::unique_lock<std::mutex> lock(mutex_);
  while (!stop_cv_.wait_for(lock, interval_, [this] { return stop_; })) {
    lock.unlock();
    try {
      const TlsPem pem = ReadTlsFiles(cert_file_, key_file_, client_ca_file_);
      last_error.reset();
      if (!(pem == published_)) {
        Publish(pem);
        published_ = pem;
        lock.lock();
        ++reloads_;
        lock.unlock();
        if (log_) {
          log_(LogLevel::kInfo,
               "TLS files changed: the new certificate is in force for new connections");
        }
      }
    } catch (const std::exception& error) {
      // Reported once per distinct problem (a file being replaced may fail one check).
      if (last_error != error.what()) {
        last_error = error.what();
        if (log_) {
          log_(LogLevel::kWarning, std::string("TLS files changed but are not valid: ") +
                                       error.what() + "; the previous certificate stays in force");
        }
      }
    }
    lock.lock();
  }
}

bool IsLoopbackListenAddress(const std::string& address) {
  if (address.rfind("unix:", 0) == 0 || address.rfind("unix-abstract:", 0) == 0) return true;
  std::string rest = address;
  for (const std::string prefix : {"ipv4:", "ipv6:"}) {
    if (rest.rfind(prefix, 0) == 0) rest = rest.substr(prefix.size());
  }
  const size_t colon = rest.rfind(':');
  if (colon == std::string::npos) return false;
  std::string host = rest.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') {
    host = host.substr(1, host.size() - 2);
  }
  if (host == "localhost") return true;
  in_addr ipv4{};
  if (inet_pton(AF_INET, host.c_str(), &ipv4) == 1) {
    return (ntohl(ipv4.s_addr) >> 24) == 127;
  }
  in6_addr ipv6{};
  if (inet_pton(AF_INET6, host.c_str(), &ipv6) == 1) return IN6_IS_ADDR_LOOPBACK(&ipv6);
  return false;
}

void CheckListenSecurity(const std::string& address, const ListenSecurity& security) {
  if (security.insecure || IsLoopbackListenAddress(address)) return;
  std::string missing;
  if (!security.tls) missing = "TLS (--tls-cert and --tls-key)";
  if (!security.tokens && !security.client_certificates) {
    missing += std::string(missing.empty() ? "" : " and ") +
               "authentication (--auth-tokens, or client certificates with --tls-client-ca)";
  }
  if (missing.empty()) return;
  throw InvalidArgumentError(
      "refusing to serve on '" + address + "' without " + missing +
      ": it is not a loopback address, so anyone who can reach it could use every map and read "
      "the event streams, poses and tokens in the clear. Give --tls-cert, --tls-key and "
      "--auth-tokens (docs/deploy.md, \"Secure defaults\"), listen on 127.0.0.1, or add "
      "--insecure to serve this way on a network you trust");
}

std::string DescribeListenSecurity(const std::string& address, const ListenSecurity& security) {
  std::string text = security.tls ? "TLS" : "plaintext";
  if (security.client_certificates) text += ", client certificates required (mutual TLS)";
  text += security.tokens ? ", bearer tokens" : ", no tokens";
  if (IsLoopbackListenAddress(address)) return text + " (loopback only)";
  if (security.tls && (security.tokens || security.client_certificates)) return text;
  return "INSECURE (--insecure): " + text + " on a network address";
}

}  // namespace evloc::service
