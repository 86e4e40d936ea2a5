// Typed errors thrown by evloc library code. Library code never prints or exits: it throws one of
// these, and the command-line tools and the service translate them into exit codes and gRPC
// status codes (see docs/conventions.md, "Errors").
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>

namespace evloc {

// Base of every evloc error; what() is a complete sentence a user can act on.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A caller passed a value outside its documented domain (bad option, invalid camera, ...).
class InvalidArgumentError : public Error {
 public:
  using Error::Error;
};

// A file or stream could not be opened, read or written.
class IoError : public Error {
 public:
  using Error::Error;
};

// A file's content is malformed. The message names the source and the position: a line number
// for text formats, a byte offset for binary formats.
class ParseError : public Error {
 public:
  // `source` is a file name or stream description; `position` is e.g. "line 12" or "byte 4096".
  ParseError(const std::string& source, const std::string& position, const std::string& what)
      : Error(source + ": " + position + ": " + what) {}
  // Convenience for text formats.
  static ParseError AtLine(const std::string& source, int64_t line, const std::string& what) {
    return ParseError(source, "line " + std::to_string(line), what);
  }
  // Convenience for binary formats.
  static ParseError AtByte(const std::string& source, uint64_t byte, const std::string& what) {
    return ParseError(source, "byte " + std::to_string(byte), what);
  }
};

}  // namespace evloc
