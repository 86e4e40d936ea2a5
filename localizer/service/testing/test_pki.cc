#include "localizer/service/testing/test_pki.h"

#include <cstdlib>
#include <fstream>

namespace evloc::service::testing {
namespace {

// Runs a shell command quietly; true when it succeeded.
bool Run(const std::string& command) {
  return std::system((command + " > /dev/null 2>&1").c_str()) == 0;
}

}  // namespace

bool HaveOpenssl() { return Run("openssl version"); }

bool TestPki::MakeCa(const std::string& name) const {
  return Run(
      "openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 1 -subj "
      "/CN=" +
      name + " -keyout '" + Key(name).string() + "' -out '" + Cert(name).string() + "'");
}

bool TestPki::MakeLeaf(const std::string& name, const std::string& ca) const {
  const auto csr = folder_ / (name + ".csr");
  const auto extensions = folder_ / (name + ".ext");
  {
    std::ofstream file(extensions);
    file << "subjectAltName=DNS:localhost,IP:127.0.0.1\n";
  }
  return Run("openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -subj "
             "/CN=localhost -keyout '" +
             Key(name).string() + "' -out '" + csr.string() + "'") &&
         Run("openssl x509 -req -days 1 -in '" + csr.string() + "' -CA '" + Cert(ca).string() +
             "' -CAkey '" + Key(ca).string() + "' -CAcreateserial -extfile '" +
             extensions.string() + "' -out '" + Cert(name).string() + "'");
}

}  // namespace evloc::service::testing
