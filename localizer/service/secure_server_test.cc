// The server's secure defaults (issue 14, findings 4 and 11): refusing open network listeners,
// token files read strictly and again when they change, TLS certificates read again when they
// change, and mutual TLS. Test certificates are made at test time with the openssl command.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "localizer/service/localizer_server.h"
#include "localizer/service/serve_command.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/service/testing/test_pki.h"

namespace evloc::service {
namespace {

// Writes `content` to `path` through a temporary file and a rename (as Kubernetes and a careful
// operator replace files).
void ReplaceFile(const std::filesystem::path& path, const std::string& content) {
  const std::filesystem::path staging = path.string() + ".new";
  {
    std::ofstream file(staging);
    file << content;
  }
  std::filesystem::rename(staging, path);
}

// Waits (at most `seconds`) until `condition` holds.
bool Eventually(const std::function<bool()>& condition, int seconds) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
  while (std::chrono::steady_clock::now() < end) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return condition();
}

// ListMaps over TLS trusting only `ca`, presenting `client` (a TestPki leaf name) when not
// empty; the status.
grpc::Status ListMapsOverTls(int port, const testing::TestPki& pki, const std::string& ca,
                             const std::string& client = "") {
  grpc::SslCredentialsOptions ssl;
  ssl.pem_root_certs = ReadFileToString(pki.Cert(ca));
  if (!client.empty()) {
    ssl.pem_private_key = ReadFileToString(pki.Key(client));
    ssl.pem_cert_chain = ReadFileToString(pki.Cert(client));
  }
  grpc::ChannelArguments arguments;
  arguments.SetSslTargetNameOverride("localhost");
  auto stub = api::Localizer::NewStub(grpc::CreateCustomChannel(
      "127.0.0.1:" + std::to_string(port), grpc::SslCredentials(ssl), arguments));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  api::ListMapsResponse list;
  return stub->ListMaps(&context, {}, &list);
}

// ListMaps over plaintext with `token`; the status.
grpc::Status ListMapsWithToken(int port, const std::string& token) {
  auto stub = testing::ConnectStub(port);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  context.AddMetadata("authorization", "Bearer " + token);
  api::ListMapsResponse list;
  return stub->ListMaps(&context, {}, &list);
}

class SecureServerTest : public ::testing::Test {
 protected:
  SecureServerTest() {
    testing::WriteTestMap(maps_.path(), testing::kTestMapName, testing::TestMap());
  }

  LocalizerServerOptions Options() const {
    LocalizerServerOptions options = testing::TestServerOptions(maps_.path());
    options.reload_interval_s = 1;
    return options;
  }

  void Start(const LocalizerServerOptions& options) {
    server_ = std::make_unique<LocalizerServer>(options, [this](const std::string& line) {
      std::lock_guard<std::mutex> lock(log_mutex_);
      log_.push_back(line);
    });
  }

  // Starts a TLS server whose files (cert_, key_) hold a copy of the TestPki pair `leaf`.
  void StartTlsWithCopyOf(const testing::TestPki& pki, const std::string& leaf) {
    ReplaceFile(cert_, ReadFileToString(pki.Cert(leaf)));
    ReplaceFile(key_, ReadFileToString(pki.Key(leaf)));
    LocalizerServerOptions options = Options();
    options.tls_cert_file = cert_;
    options.tls_key_file = key_;
    Start(options);
  }

  testing::TemporaryFolder maps_;
  testing::TemporaryFolder files_;
  // The server's certificate and key files (the TLS tests replace them while it runs).
  const std::filesystem::path cert_ = files_.path() / "server.crt";
  const std::filesystem::path key_ = files_.path() / "server.key";
  std::mutex log_mutex_;
  std::vector<std::string> log_;
  std::unique_ptr<LocalizerServer> server_;
};

// Finding 4: `serve` on a network address without TLS and tokens refused to start only when
// the address was in use; it now refuses with what, why and what to do, unless --insecure.
TEST(SecureDefaults, ServeOnANetworkAddressWithoutTlsAndTokensIsRefused) {
  testing::TemporaryFolder folder;
  const std::string maps = folder.path().string();
  try {
    ParseServeCommandLine({"serve", "--maps", maps, "--listen", "0.0.0.0:50051"});
    FAIL() << "expected an InvalidArgumentError";
  } catch (const InvalidArgumentError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("refusing to serve on '0.0.0.0:50051'"), std::string::npos) << message;
    EXPECT_NE(message.find("--insecure"), std::string::npos) << message;
  }
  // Tokens alone would travel in the clear.
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--listen", "[::]:50051",
                                      "--auth-tokens", "tokens.txt"}),
               InvalidArgumentError);
  const ServeCommand insecure =
      ParseServeCommandLine({"serve", "--maps", maps, "--listen", "0.0.0.0:50051", "--insecure"});
  EXPECT_TRUE(insecure.server.insecure);
  EXPECT_NE(insecure.server.Describe().find("security: INSECURE"), std::string::npos);
  const ServeCommand secured = ParseServeCommandLine(
      {"serve", "--maps", maps, "--listen", "0.0.0.0:50051", "--tls-cert", "c.pem", "--tls-key",
       "k.pem", "--tls-client-ca", "ca.pem", "--reload-interval", "3", "--metrics", "9464"});
  EXPECT_EQ(secured.server.tls_client_ca_file, "ca.pem");
  EXPECT_EQ(secured.server.reload_interval_s, 3);
  // A bare metrics port listens on loopback only.
  EXPECT_EQ(secured.server.metrics_address, "127.0.0.1:9464");
  // Loopback stays open for tests and local tools.
  EXPECT_NO_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--listen", "127.0.0.1:0"}));
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--tls-client-ca", "ca.pem"}),
               InvalidArgumentError);
  EXPECT_THROW(ParseServeCommandLine({"serve", "--maps", maps, "--reload-interval", "0"}),
               InvalidArgumentError);
}

// The command itself: exit code 2 and the message on stderr, before anything listens.
TEST(SecureDefaults, TheCommandExitsWith2AndSaysWhatToDo) {
  testing::TemporaryFolder folder;
  const auto err = folder.path() / "stderr.txt";
  // Bounded: a server that starts anyway is stopped (SIGTERM, exit 0) after 20 s.
  const std::string command = "timeout 20 " + std::string(EVLOC_LOCALIZER) + " serve --maps '" +
                              folder.path().string() + "' --listen 0.0.0.0:0 > /dev/null 2> '" +
                              err.string() + "'";
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 2);
  const std::string message = ReadFileToString(err);
  EXPECT_NE(message.find("refusing to serve on '0.0.0.0:0' without TLS"), std::string::npos)
      << message;
  EXPECT_NE(message.find("--insecure"), std::string::npos) << message;
}

TEST_F(SecureServerTest, TheLibraryRefusesAnOpenNetworkListenerToo) {
  LocalizerServerOptions options = Options();
  options.listen_address = "0.0.0.0:0";
  EXPECT_THROW(Start(options), InvalidArgumentError);
}

// Finding 11: the line `TOKEN ,` gave that token every map.
TEST_F(SecureServerTest, ATokenLineWithAnEmptyMapListStopsTheServerFromStarting) {
  const auto tokens = files_.path() / "tokens.txt";
  ReplaceFile(tokens, "alpha rectangles\nintruder ,\n");
  LocalizerServerOptions options = Options();
  options.auth_tokens_file = tokens;
  try {
    Start(options);
    FAIL() << "expected a ParseError; the server answers intruder with "
           << ListMapsWithToken(server_->port(), "intruder").error_code();
  } catch (const ParseError& error) {
    EXPECT_NE(std::string(error.what()).find(tokens.string() + ": line 2"), std::string::npos)
        << error.what();
  }
}

TEST_F(SecureServerTest, TheTokenFileIsReadAgainWhenItChanges) {
  const auto tokens = files_.path() / "tokens.txt";
  ReplaceFile(tokens, "alpha *\n");
  LocalizerServerOptions options = Options();
  options.auth_tokens_file = tokens;
  Start(options);
  EXPECT_TRUE(ListMapsWithToken(server_->port(), "alpha").ok());
  EXPECT_EQ(ListMapsWithToken(server_->port(), "beta").error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  ReplaceFile(tokens, "beta rectangles\n");
  EXPECT_TRUE(Eventually([&] { return ListMapsWithToken(server_->port(), "beta").ok(); }, 10));
  EXPECT_EQ(ListMapsWithToken(server_->port(), "alpha").error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
}

TEST_F(SecureServerTest, CertificatesAreReadAgainWhenTheyChange) {
  if (!testing::HaveOpenssl()) GTEST_SKIP() << "the openssl command is not installed";
  testing::TestPki pki(files_.path());
  ASSERT_TRUE(pki.MakeCa("old-ca") && pki.MakeLeaf("old-server", "old-ca"));
  ASSERT_TRUE(pki.MakeCa("new-ca") && pki.MakeLeaf("new-server", "new-ca"));
  StartTlsWithCopyOf(pki, "old-server");
  const int port = server_->port();
  const grpc::Status old_status = ListMapsOverTls(port, pki, "old-ca");
  EXPECT_TRUE(old_status.ok()) << old_status.error_message();
  EXPECT_FALSE(ListMapsOverTls(port, pki, "new-ca").ok());

  ReplaceFile(key_, ReadFileToString(pki.Key("new-server")));
  ReplaceFile(cert_, ReadFileToString(pki.Cert("new-server")));
  EXPECT_TRUE(Eventually([&] { return ListMapsOverTls(port, pki, "new-ca").ok(); }, 15))
      << "a client trusting only the new CA cannot connect after the certificate changed";
  EXPECT_FALSE(ListMapsOverTls(port, pki, "old-ca").ok());
}

TEST_F(SecureServerTest, InvalidNewTlsFilesKeepThePreviousCertificateInForce) {
  if (!testing::HaveOpenssl()) GTEST_SKIP() << "the openssl command is not installed";
  testing::TestPki pki(files_.path());
  ASSERT_TRUE(pki.MakeCa("ca") && pki.MakeLeaf("leaf", "ca"));
  ASSERT_TRUE(pki.MakeCa("other-ca") && pki.MakeLeaf("other", "other-ca"));
  StartTlsWithCopyOf(pki, "leaf");
  const int port = server_->port();
  ASSERT_TRUE(ListMapsOverTls(port, pki, "ca").ok());
  // A certificate that is not PEM (a half-written file), then a key that does not belong to
  // the certificate (a pair replaced one file at a time): gRPC's file watcher alone installs
  // either, and every handshake fails while the files are so (ServerTlsFiles in auth.h).
  ReplaceFile(cert_, "not a certificate\n");
  std::this_thread::sleep_for(std::chrono::milliseconds(3500));
  const grpc::Status garbage = ListMapsOverTls(port, pki, "ca");
  EXPECT_TRUE(garbage.ok()) << garbage.error_message();
  ReplaceFile(cert_, ReadFileToString(pki.Cert("leaf")));
  ReplaceFile(key_, ReadFileToString(pki.Key("other")));
  std::this_thread::sleep_for(std::chrono::milliseconds(3500));
  const grpc::Status mismatched = ListMapsOverTls(port, pki, "ca");
  EXPECT_TRUE(mismatched.ok()) << mismatched.error_message();
  ReplaceFile(key_, ReadFileToString(pki.Key("leaf")));
  std::this_thread::sleep_for(std::chrono::milliseconds(3500));
  const grpc::Status restored = ListMapsOverTls(port, pki, "ca");
  EXPECT_TRUE(restored.ok()) << restored.error_message();
  // Each bad version was reported once; none was published.
  std::lock_guard<std::mutex> lock(log_mutex_);
  int reports = 0;
  for (const std::string& line : log_) reports += line.find("are not valid") != std::string::npos;
  EXPECT_EQ(reports, 2);
}

TEST_F(SecureServerTest, MutualTlsRefusesClientsWithoutACertificateOfTheClientCa) {
  if (!testing::HaveOpenssl()) GTEST_SKIP() << "the openssl command is not installed";
  testing::TestPki pki(files_.path());
  ASSERT_TRUE(pki.MakeCa("server-ca") && pki.MakeLeaf("server", "server-ca"));
  ASSERT_TRUE(pki.MakeCa("client-ca") && pki.MakeLeaf("camera", "client-ca"));
  ASSERT_TRUE(pki.MakeCa("rogue-ca") && pki.MakeLeaf("rogue", "rogue-ca"));
  LocalizerServerOptions options = Options();
  options.tls_cert_file = pki.Cert("server");
  options.tls_key_file = pki.Key("server");
  options.tls_client_ca_file = pki.Cert("client-ca");
  Start(options);
  const int port = server_->port();
  const grpc::Status with_certificate = ListMapsOverTls(port, pki, "server-ca", "camera");
  EXPECT_TRUE(with_certificate.ok()) << with_certificate.error_message();
  EXPECT_FALSE(ListMapsOverTls(port, pki, "server-ca").ok());
  EXPECT_FALSE(ListMapsOverTls(port, pki, "server-ca", "rogue").ok());
}

TEST_F(SecureServerTest, AnUnwritableTemporaryFolderIsAClearError) {
  if (!testing::HaveOpenssl()) GTEST_SKIP() << "the openssl command is not installed";
  testing::TestPki pki(files_.path());
  ASSERT_TRUE(pki.MakeCa("ca") && pki.MakeLeaf("leaf", "ca"));
  LocalizerServerOptions options = Options();
  options.tls_cert_file = pki.Cert("leaf");
  options.tls_key_file = pki.Key("leaf");
  const char* previous = std::getenv("TMPDIR");
  const std::string saved = previous != nullptr ? previous : "";
  ::setenv("TMPDIR", (files_.path() / "missing").c_str(), 1);
  try {
    Start(options);
    ADD_FAILURE() << "expected an IoError";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("TMPDIR"), std::string::npos) << error.what();
  }
  if (previous != nullptr) {
    ::setenv("TMPDIR", saved.c_str(), 1);
  } else {
    ::unsetenv("TMPDIR");
  }
}

TEST_F(SecureServerTest, MismatchedOrMalformedTlsFilesStopTheServerFromStarting) {
  if (!testing::HaveOpenssl()) GTEST_SKIP() << "the openssl command is not installed";
  testing::TestPki pki(files_.path());
  ASSERT_TRUE(pki.MakeCa("ca") && pki.MakeLeaf("one", "ca") && pki.MakeLeaf("two", "ca"));
  LocalizerServerOptions options = Options();
  options.tls_cert_file = pki.Cert("one");
  options.tls_key_file = pki.Key("two");
  try {
    Start(options);
    FAIL() << "expected an InvalidArgumentError";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("does not belong"), std::string::npos) << error.what();
  }
  options.tls_key_file = pki.Key("one");
  options.tls_client_ca_file = pki.Key("two");
  EXPECT_THROW(Start(options), InvalidArgumentError);
}

}  // namespace
}  // namespace evloc::service
