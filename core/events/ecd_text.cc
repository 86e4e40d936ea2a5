#include "core/events/ecd_text.h"

#include <charconv>
#include <cstring>
#include <fstream>
#include <utility>

#include "core/common/error.h"

namespace evloc {
namespace {

// Longest accepted line; protects against unbounded buffering of binary garbage.
constexpr size_t kMaxLineLength = 4096;
// Bytes read from the stream at a time.
constexpr size_t kBlockSize = size_t{1} << 16;
// Largest accepted time, seconds (int64 nanoseconds reach 9.22e9 s).
constexpr int64_t kMaxSeconds = 9'000'000'000;

bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\r'; }
bool IsDigit(char c) { return c >= '0' && c <= '9'; }

// Parses an unsigned decimal integer of at most 5 digits (0..65535) at `*text`.
bool ParseCoordinate(std::string_view* text, uint16_t* value) {
  size_t length = 0;
  uint32_t number = 0;
  while (length < text->size() && IsDigit((*text)[length])) {
    number = number * 10 + static_cast<uint32_t>((*text)[length] - '0');
    if (++length > 5) return false;
  }
  if (length == 0 || number > 65535) return false;
  *value = static_cast<uint16_t>(number);
  text->remove_prefix(length);
  return true;
}

// Removes leading whitespace; returns false when there was none (a separator is required).
bool SkipRequiredSpace(std::string_view* text) {
  size_t length = 0;
  while (length < text->size() && IsSpace((*text)[length])) ++length;
  text->remove_prefix(length);
  return length > 0;
}

}  // namespace

std::optional<int64_t> ParseSecondsToNanoseconds(std::string_view text) {
  size_t position = 0;
  int64_t seconds = 0;
  while (position < text.size() && IsDigit(text[position])) {
    seconds = seconds * 10 + (text[position] - '0');
    if (seconds > kMaxSeconds) return std::nullopt;
    ++position;
  }
  const size_t integer_digits = position;
  int64_t nanoseconds = 0;
  size_t fraction_digits = 0;
  if (position < text.size() && text[position] == '.') {
    ++position;
    bool round_up = false;
    while (position < text.size() && IsDigit(text[position])) {
      if (fraction_digits < 9) {
        nanoseconds = nanoseconds * 10 + (text[position] - '0');
      } else if (fraction_digits == 9) {
        round_up = text[position] >= '5';
      }
      ++fraction_digits;
      ++position;
    }
    for (size_t i = fraction_digits; i < 9; ++i) nanoseconds *= 10;
    if (round_up) ++nanoseconds;
  }
  if (position != text.size() || integer_digits + fraction_digits == 0) return std::nullopt;
  return seconds * 1'000'000'000 + nanoseconds;
}

EcdTextReader::EcdTextReader(const std::filesystem::path& path,
                             std::optional<SensorSize> sensor_size)
    : stream_(std::make_unique<std::ifstream>(path, std::ios::binary)),
      source_(path.string()),
      sensor_size_(sensor_size) {
  if (!*stream_) throw IoError(source_ + ": cannot open");
  if (sensor_size_) sensor_size_->Check();
}

EcdTextReader::EcdTextReader(std::unique_ptr<std::istream> stream, std::string source,
                             std::optional<SensorSize> sensor_size)
    : stream_(std::move(stream)), source_(std::move(source)), sensor_size_(sensor_size) {
  if (!stream_) throw InvalidArgumentError("EcdTextReader: null stream");
  if (sensor_size_) sensor_size_->Check();
}

bool EcdTextReader::NextLine(std::string_view* line) {
  while (true) {
    const size_t newline = buffer_.find('\n', position_);
    if (newline != std::string::npos) {
      *line = std::string_view(buffer_).substr(position_, newline - position_);
      position_ = newline + 1;
      if (line->size() > kMaxLineLength) {
        throw ParseError::AtLine(source_, line_number_ + 1,
                                 "line longer than " + std::to_string(kMaxLineLength) + " bytes");
      }
      return true;
    }
    if (buffer_.size() - position_ > kMaxLineLength) {
      throw ParseError::AtLine(source_, line_number_ + 1,
                               "line longer than " + std::to_string(kMaxLineLength) + " bytes");
    }
    if (end_of_stream_) {
      if (position_ == buffer_.size()) return false;
      *line = std::string_view(buffer_).substr(position_);
      position_ = buffer_.size();
      return true;
    }
    buffer_.erase(0, position_);
    position_ = 0;
    const size_t kept = buffer_.size();
    buffer_.resize(kept + kBlockSize);
    stream_->read(buffer_.data() + kept, static_cast<std::streamsize>(kBlockSize));
    buffer_.resize(kept + static_cast<size_t>(stream_->gcount()));
    if (stream_->bad()) throw IoError(source_ + ": read failed");
    if (stream_->eof() || stream_->gcount() == 0) end_of_stream_ = true;
  }
}

void EcdTextReader::ParseLine(std::string_view line, EventBuffer* out) {
  auto fail = [&](const std::string& what) {
    return ParseError::AtLine(source_, line_number_, what + " (expected 't[s] x y p')");
  };
  std::string_view rest = line;
  const size_t time_end = rest.find_first_of(" \t\r");
  const auto t_ns = ParseSecondsToNanoseconds(rest.substr(0, time_end));
  if (!t_ns)
    throw fail("invalid time '" + std::string(rest.substr(0, std::min<size_t>(time_end, 40))) +
               "'");
  rest.remove_prefix(time_end == std::string_view::npos ? rest.size() : time_end);
  uint16_t x = 0, y = 0;
  if (!SkipRequiredSpace(&rest) || !ParseCoordinate(&rest, &x)) throw fail("invalid x");
  if (!SkipRequiredSpace(&rest) || !ParseCoordinate(&rest, &y)) throw fail("invalid y");
  if (!SkipRequiredSpace(&rest) || rest.empty() || (rest[0] != '0' && rest[0] != '1')) {
    throw fail("invalid polarity (must be 0 or 1)");
  }
  const int8_t polarity = rest[0] == '1' ? int8_t{1} : int8_t{-1};
  rest.remove_prefix(1);
  while (!rest.empty() && IsSpace(rest.front())) rest.remove_prefix(1);
  if (!rest.empty()) throw fail("unexpected text after the polarity");
  if (sensor_size_ && !sensor_size_->Contains(x, y)) {
    throw fail("event (" + std::to_string(x) + ", " + std::to_string(y) + ") outside the sensor");
  }
  out->push_back({*t_ns, x, y, polarity});
}

size_t EcdTextReader::Read(size_t max_events, EventBuffer* out) {
  if (out == nullptr) throw InvalidArgumentError("EcdTextReader::Read: output buffer is null");
  size_t appended = 0;
  std::string_view line;
  while (appended < max_events && NextLine(&line)) {
    ++line_number_;
    size_t first = 0;
    while (first < line.size() && IsSpace(line[first])) ++first;
    if (first == line.size() || line[first] == '#') continue;
    ParseLine(line.substr(first), out);
    ++appended;
  }
  return appended;
}

EcdTextWriter::EcdTextWriter(const std::filesystem::path& path) : file_(path) {}

void EcdTextWriter::Write(const EventBuffer& events) {
  if (closed_) throw InvalidArgumentError(file_.path().string() + ": write after Close()");
  if (!events.IsConsistent()) {
    throw InvalidArgumentError("EcdTextWriter::Write: the event buffer's arrays differ in length");
  }
  for (size_t i = 0; i < events.size(); ++i) {
    if (events.t_ns[i] < 0 || (events.polarity[i] != 1 && events.polarity[i] != -1)) {
      throw InvalidArgumentError("EcdTextWriter::Write: event " + std::to_string(i) +
                                 " has a negative time or a polarity other than +1/-1");
    }
  }
  text_.clear();
  char digits[24];
  const auto append_number = [&](uint64_t value) {
    text_.append(digits, std::to_chars(digits, digits + sizeof(digits), value).ptr);
  };
  for (size_t i = 0; i < events.size(); ++i) {
    append_number(static_cast<uint64_t>(events.t_ns[i] / 1'000'000'000));
    // Nine fraction digits, zero-padded: exact nanoseconds.
    const auto fraction = static_cast<uint64_t>(events.t_ns[i] % 1'000'000'000);
    char fraction_digits[10] = {'.', '0', '0', '0', '0', '0', '0', '0', '0', '0'};
    uint64_t remaining = fraction;
    for (int digit = 9; digit >= 1; --digit) {
      fraction_digits[digit] = static_cast<char>('0' + remaining % 10);
      remaining /= 10;
    }
    text_.append(fraction_digits, 10);
    text_.push_back(' ');
    append_number(events.x[i]);
    text_.push_back(' ');
    append_number(events.y[i]);
    text_.push_back(' ');
    text_.push_back(events.polarity[i] > 0 ? '1' : '0');
    text_.push_back('\n');
  }
  file_.stream().write(text_.data(), static_cast<std::streamsize>(text_.size()));
  if (!file_.stream()) throw IoError(file_.path().string() + ": write failed");
}

void EcdTextWriter::Close() {
  if (closed_) return;
  file_.Commit();
  closed_ = true;
}

}  // namespace evloc
