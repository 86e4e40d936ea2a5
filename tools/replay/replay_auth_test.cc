// evloc-replay's credentials (issue 14, finding 11): the bearer token from a file instead of the
// command line, and a client certificate for servers that require one (mutual TLS).
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <sstream>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "localizer/service/localizer_server.h"
#include "localizer/service/testing/service_fixture.h"
#include "localizer/service/testing/test_pki.h"
#include "tools/replay/replay.h"

namespace evloc::replay {
namespace {

namespace fixture = service::testing;

void WriteText(const std::filesystem::path& path, const std::string& text) {
  std::ofstream file(path);
  file << text;
}

// The ParseError message of reading a token file holding `text` (empty when none).
std::string TokenFileError(const std::filesystem::path& folder, const std::string& text) {
  const auto path = folder / "token";
  WriteText(path, text);
  try {
    ReadTokenFile(path);
  } catch (const ParseError& error) {
    return error.what();
  }
  return "";
}

TEST(ReplayTokenFile, FlagsMapToOptions) {
  const ReplayCommand command = ParseReplayCommandLine(
      {"--server", "127.0.0.1:1", "--map", "m", "--dataset", "d", "--out", "o.txt", "--token-file",
       "token.txt", "--tls-ca", "ca.pem", "--tls-cert", "client.crt", "--tls-key", "client.key"});
  EXPECT_EQ(command.options.token_file, std::filesystem::path("token.txt"));
  EXPECT_FALSE(command.options.token.has_value());
  EXPECT_EQ(command.options.tls_cert_file, std::filesystem::path("client.crt"));
  EXPECT_EQ(command.options.tls_key_file, std::filesystem::path("client.key"));
  const std::vector<std::string> base = {"--server",  "x", "--map", "m",
                                         "--dataset", "d", "--out", "o"};
  auto with = [&base](std::vector<std::string> extra) {
    extra.insert(extra.begin(), base.begin(), base.end());
    return extra;
  };
  EXPECT_THROW(ParseReplayCommandLine(with({"--token", "T", "--token-file", "t"})),
               InvalidArgumentError);
  EXPECT_THROW(ParseReplayCommandLine(with({"--tls-ca", "ca", "--tls-cert", "c"})),
               InvalidArgumentError);
  EXPECT_THROW(ParseReplayCommandLine(with({"--tls-cert", "c", "--tls-key", "k"})),
               InvalidArgumentError);
}

TEST(ReplayTokenFile, ReadsOneTokenAndRejectsAnythingElse) {
  fixture::TemporaryFolder folder;
  const auto path = folder.path() / "token";
  WriteText(path, "\n  s3cret-token \r\n\n");
  EXPECT_EQ(ReadTokenFile(path), "s3cret-token");
  EXPECT_NE(TokenFileError(folder.path(), ""), "");
  EXPECT_NE(TokenFileError(folder.path(), " \n\t\n"), "");
  EXPECT_NE(TokenFileError(folder.path(), "two words\n").find("line 1"), std::string::npos);
  EXPECT_NE(TokenFileError(folder.path(), "one\ntwo\n").find("line 2"), std::string::npos);
  EXPECT_THROW(ReadTokenFile(folder.path() / "missing"), IoError);
}

// The secret no longer has to be on the command line: a replay against a server with tokens,
// its token in a file.
TEST(ReplayTokenFile, ReplaysWithTheTokenFromAFile) {
  fixture::TemporaryFolder folder;
  fixture::WriteTestMap(folder.path() / "maps", fixture::kTestMapName, fixture::TestMap());
  WriteText(folder.path() / "tokens.txt", std::string("camera-token ") + fixture::kTestMapName);
  service::LocalizerServerOptions server_options =
      fixture::TestServerOptions(folder.path() / "maps");
  server_options.auth_tokens_file = folder.path() / "tokens.txt";
  service::LocalizerServer server(server_options);

  ReplayOptions options;
  options.server = "127.0.0.1:" + std::to_string(server.port());
  options.map_name = fixture::kTestMapName;
  options.dataset = fixture::WriteTestDataset(folder.path(), 200'000'000);
  options.output = folder.path() / "trajectory.txt";
  options.speed = std::nullopt;
  options.duration_s = 0.1;
  WriteText(folder.path() / "token", "camera-token\n");
  options.token_file = folder.path() / "token";
  std::ostringstream log;
  EXPECT_GE(RunReplay(options, log).trajectory.size(), 25u);

  WriteText(folder.path() / "token", "wrong-token\n");
  EXPECT_THROW(RunReplay(options, log), Error) << "a wrong token in the file";
}

// --token still works but warns on stderr that the secret is visible.
TEST(ReplayTokenFile, TheTokenFlagWarnsThatTheSecretIsVisible) {
  fixture::TemporaryFolder folder;
  const auto err = folder.path() / "stderr.txt";
  const std::string command = std::string(EVLOC_REPLAY) +
                              " --health-check --server 127.0.0.1:1 --health-timeout 0.2 "
                              "--token T > /dev/null 2> '" +
                              err.string() + "'";
  EXPECT_NE(std::system(command.c_str()), 0);  // Nothing listens on port 1.
  const std::string message = ReadFileToString(err);
  EXPECT_NE(message.find("warning: --token shows the secret"), std::string::npos) << message;
  EXPECT_NE(message.find("--token-file"), std::string::npos) << message;
}

// A server with --tls-client-ca: the health check (the container's probe) needs the client
// certificate.
TEST(ReplayMutualTls, TheHealthCheckPresentsTheClientCertificate) {
  if (!fixture::HaveOpenssl()) GTEST_SKIP() << "the openssl command is not installed";
  fixture::TemporaryFolder folder;
  fixture::TestPki pki(folder.path());
  ASSERT_TRUE(pki.MakeCa("ca") && pki.MakeLeaf("server", "ca") && pki.MakeLeaf("probe", "ca"));
  fixture::WriteTestMap(folder.path() / "maps", fixture::kTestMapName, fixture::TestMap());
  service::LocalizerServerOptions server_options =
      fixture::TestServerOptions(folder.path() / "maps");
  server_options.tls_cert_file = pki.Cert("server");
  server_options.tls_key_file = pki.Key("server");
  server_options.tls_client_ca_file = pki.Cert("ca");
  service::LocalizerServer server(server_options);

  ReplayOptions options;
  options.server = "127.0.0.1:" + std::to_string(server.port());
  options.tls_ca_file = pki.Cert("ca");
  options.tls_server_name = "localhost";
  EXPECT_THROW(CheckHealth(options, 5.0), Error) << "no client certificate";
  options.tls_cert_file = pki.Cert("probe");
  options.tls_key_file = pki.Key("probe");
  EXPECT_EQ(CheckHealth(options, 5.0), "SERVING");
}

}  // namespace
}  // namespace evloc::replay
