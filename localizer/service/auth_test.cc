#include "localizer/service/auth.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <thread>

#include "core/common/error.h"
#include "localizer/service/testing/service_fixture.h"

namespace evloc::service {
namespace {

std::string Hex(const Sha256Digest& digest) {
  std::string text;
  char pair[3];
  for (const uint8_t byte : digest) {
    std::snprintf(pair, sizeof(pair), "%02x", byte);
    text += pair;
  }
  return text;
}

// Writes `content` to `path` through a temporary file and a rename, as an operator should.
void ReplaceFile(const std::filesystem::path& path, const std::string& content) {
  const std::filesystem::path staging = path.string() + ".new";
  {
    std::ofstream file(staging);
    file << content;
  }
  std::filesystem::rename(staging, path);
}

// The message of the ParseError that parsing `text` throws (empty when it does not throw).
std::string ParseErrorOf(const std::string& text) {
  try {
    TokenTable::Parse(text, "tokens.txt");
  } catch (const ParseError& error) {
    return error.what();
  }
  return "";
}

TEST(Sha256, MatchesTheStandardTestVectors) {
  EXPECT_EQ(Hex(Sha256("abc")), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(Hex(Sha256("")), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
}

// Finding 11 of issue 14: `TOKEN ,` was read as an empty map list, which meant every map.
TEST(TokenTable, AnEmptyMapListIsAParseErrorNamingFileAndLine) {
  const std::string comma = ParseErrorOf("# tokens\nsecret ,\n");
  EXPECT_NE(comma.find("tokens.txt: line 2"), std::string::npos) << comma;
  EXPECT_NE(comma.find("empty map name"), std::string::npos) << comma;
  // The secret never appears in the message (it goes to logs).
  EXPECT_EQ(comma.find("secret"), std::string::npos) << comma;
  const std::string bare = ParseErrorOf("secret\n");
  EXPECT_NE(bare.find("tokens.txt: line 1"), std::string::npos) << bare;
  EXPECT_NE(bare.find("`*`"), std::string::npos) << bare;
  for (const std::string maps : {",", ",,", "a,", ",a", "a,,b", "*,a", "a,*"}) {
    EXPECT_NE(ParseErrorOf("token " + maps + "\n"), "") << "maps '" << maps << "'";
  }
  EXPECT_NE(ParseErrorOf("token a b\n"), "");
  EXPECT_NE(ParseErrorOf("token *\nother a\ntoken b\n").find("line 3"), std::string::npos);
  EXPECT_NE(ParseErrorOf("sha256:abcd *\n"), "");
  EXPECT_NE(ParseErrorOf("sha256:" + std::string(64, 'g') + " *\n"), "");
}

TEST(TokenTable, StarAllowsEveryMapAndAListOnlyItsMaps) {
  const TokenTable table =
      TokenTable::Parse("# comment\n\nall *  # every map\nsome a,b\n", "tokens.txt");
  EXPECT_EQ(table.size(), 2u);
  EXPECT_TRUE(table.Allows("all", "a"));
  EXPECT_TRUE(table.Allows("all", "anything"));
  EXPECT_TRUE(table.Allows("some", "a"));
  EXPECT_TRUE(table.Allows("some", "b"));
  EXPECT_FALSE(table.Allows("some", "c"));
  EXPECT_FALSE(table.Allows("nobody", "a"));
}

TEST(TokenTable, ComparesWholeDigestsOfTheToken) {
  const TokenTable table = TokenTable::Parse("s3cret-token *\n", "tokens.txt");
  EXPECT_TRUE(table.Knows("s3cret-token"));
  // A prefix, an extension, one changed character at either end, the empty token.
  EXPECT_FALSE(table.Knows("s3cret-toke"));
  EXPECT_FALSE(table.Knows("s3cret-token "));
  EXPECT_FALSE(table.Knows("s3cret-tokex"));
  EXPECT_FALSE(table.Knows("t3cret-token"));
  EXPECT_FALSE(table.Knows(""));
  // A line may give the digest instead of the token: the file then holds no secret.
  const TokenTable hashed =
      TokenTable::Parse("sha256:" + Hex(Sha256("s3cret-token")) + " map\n", "tokens.txt");
  EXPECT_TRUE(hashed.Allows("s3cret-token", "map"));
  EXPECT_FALSE(hashed.Knows("sha256:" + Hex(Sha256("s3cret-token"))));
  // The same token as digest and in the clear is a duplicate.
  EXPECT_NE(ParseErrorOf("s3cret-token *\nsha256:" + Hex(Sha256("s3cret-token")) + " a\n"), "");
}

TEST(TokenTable, ReadNamesAnUnreadableFile) {
  try {
    TokenTable::Read("/nonexistent/tokens.txt");
    FAIL() << "expected an IoError";
  } catch (const IoError& error) {
    EXPECT_NE(std::string(error.what()).find("/nonexistent/tokens.txt"), std::string::npos);
  }
}

// A token file "alpha *" checked on every lookup, and its log.
class TokenFileTest : public ::testing::Test {
 protected:
  testing::TemporaryFolder folder;
  const std::filesystem::path path = folder.path() / "tokens.txt";
  std::vector<std::string> log;
  // The file is written first (in order of declaration), then read.
  TokenFile tokens{(ReplaceFile(path, "alpha *\n"), path), std::chrono::milliseconds(0),
                   [this](LogLevel, const std::string& line) { log.push_back(line); }};
};

TEST_F(TokenFileTest, ReadsTheFileAgainWhenItChanges) {
  EXPECT_TRUE(tokens.Knows("alpha"));
  EXPECT_FALSE(tokens.Knows("beta"));
  ReplaceFile(path, "beta map\n");
  EXPECT_TRUE(tokens.Allows("beta", "map"));
  EXPECT_FALSE(tokens.Knows("alpha"));
  EXPECT_EQ(tokens.reloads(), 1);
  ASSERT_EQ(log.size(), 1u);
  EXPECT_NE(log[0].find("read again, 1 tokens"), std::string::npos) << log[0];
}

TEST_F(TokenFileTest, KeepsTheLastGoodTokensWhenTheFileBecomesInvalid) {
  ReplaceFile(path, "alpha *\nbeta ,\n");
  EXPECT_TRUE(tokens.Knows("alpha"));
  EXPECT_FALSE(tokens.Knows("beta"));
  ASSERT_EQ(log.size(), 1u);  // Reported once, not on every lookup.
  EXPECT_NE(log[0].find("line 2"), std::string::npos) << log[0];
  EXPECT_NE(log[0].find("stay in force"), std::string::npos) << log[0];
  std::filesystem::remove(path);
  EXPECT_TRUE(tokens.Knows("alpha"));
  EXPECT_EQ(log.size(), 2u);
  ReplaceFile(path, "gamma *\n");
  EXPECT_TRUE(tokens.Knows("gamma"));
  EXPECT_FALSE(tokens.Knows("alpha"));
}

TEST(TokenFile, ChecksTheFileAtMostOncePerInterval) {
  testing::TemporaryFolder folder;
  const auto path = folder.path() / "tokens.txt";
  ReplaceFile(path, "alpha *\n");
  TokenFile tokens(path, std::chrono::hours(1));
  ReplaceFile(path, "beta *\n");
  EXPECT_TRUE(tokens.Knows("alpha"));
  EXPECT_EQ(tokens.reloads(), 0);
}

TEST(ListenAddress, OnlyLoopbackAddressesAreLoopback) {
  for (const std::string address : {"127.0.0.1:50051", "127.1.2.3:0", "localhost:50051",
                                    "[::1]:50051", "ipv4:127.0.0.1:1", "unix:/tmp/evloc.sock"}) {
    EXPECT_TRUE(IsLoopbackListenAddress(address)) << address;
  }
  for (const std::string address :
       {"0.0.0.0:50051", "[::]:50051", ":50051", "10.0.0.5:50051", "evloc.example.com:50051",
        "[::ffff:10.0.0.1]:1", "50051", "128.0.0.1:1"}) {
    EXPECT_FALSE(IsLoopbackListenAddress(address)) << address;
  }
}

// Finding 4 of issue 14: a server on a network address started open and in plaintext.
TEST(ListenSecurity, ANetworkAddressNeedsTlsAndAuthenticationOrInsecure) {
  try {
    CheckListenSecurity("0.0.0.0:50051", {});
    FAIL() << "expected an InvalidArgumentError";
  } catch (const InvalidArgumentError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("0.0.0.0:50051"), std::string::npos) << message;
    EXPECT_NE(message.find("TLS (--tls-cert and --tls-key) and authentication"), std::string::npos)
        << message;
    EXPECT_NE(message.find("--insecure"), std::string::npos) << message;
  }
  ListenSecurity tls_only;
  tls_only.tls = true;
  EXPECT_THROW(CheckListenSecurity("[::]:1", tls_only), InvalidArgumentError);
  ListenSecurity tokens_only;
  tokens_only.tokens = true;
  EXPECT_THROW(CheckListenSecurity("10.0.0.5:1", tokens_only), InvalidArgumentError);
  ListenSecurity tls_and_tokens = tls_only;
  tls_and_tokens.tokens = true;
  EXPECT_NO_THROW(CheckListenSecurity("0.0.0.0:1", tls_and_tokens));
  ListenSecurity mutual_tls = tls_only;
  mutual_tls.client_certificates = true;
  EXPECT_NO_THROW(CheckListenSecurity("0.0.0.0:1", mutual_tls));
  ListenSecurity insecure;
  insecure.insecure = true;
  EXPECT_NO_THROW(CheckListenSecurity("0.0.0.0:1", insecure));
  EXPECT_NE(DescribeListenSecurity("0.0.0.0:1", insecure).find("INSECURE"), std::string::npos);
  EXPECT_NO_THROW(CheckListenSecurity("127.0.0.1:1", {}));
  EXPECT_EQ(DescribeListenSecurity("127.0.0.1:1", {}), "plaintext, no tokens (loopback only)");
}

}  // namespace
}  // namespace evloc::service
