// Test certificates made at test time with the openssl command (never committed): CAs and
// leaf certificates for localhost / 127.0.0.1, for tests of TLS and mutual TLS.
#pragma once

#include <filesystem>
#include <string>

namespace evloc::service::testing {

// True when the openssl command can be run.
bool HaveOpenssl();

// Test certificates under one folder (P-256 keys, valid one day).
class TestPki {
 public:
  // Writes into `folder`, which must exist.
  explicit TestPki(std::filesystem::path folder) : folder_(std::move(folder)) {}

  // A self-signed CA: NAME.crt and NAME.key; false when openssl failed.
  bool MakeCa(const std::string& name) const;
  // A certificate NAME.crt / NAME.key for DNS:localhost and IP:127.0.0.1 (usable by a server
  // and by a client), signed by the CA `ca` (made by MakeCa); false when openssl failed.
  bool MakeLeaf(const std::string& name, const std::string& ca) const;

  // The certificate file of `name`.
  std::filesystem::path Cert(const std::string& name) const { return folder_ / (name + ".crt"); }
  // The private key file of `name`.
  std::filesystem::path Key(const std::string& name) const { return folder_ / (name + ".key"); }

 private:
  std::filesystem::path folder_;
};

}  // namespace evloc::service::testing
