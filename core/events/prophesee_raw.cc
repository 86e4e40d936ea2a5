#include "core/events/prophesee_raw.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <fstream>
#include <utility>

#include "core/common/error.h"

namespace evloc {
namespace {

// Longest accepted header line.
constexpr size_t kMaxHeaderLine = 4096;
// Payload bytes decoded at a time.
constexpr size_t kBlockSize = size_t{1} << 16;

std::string Trim(std::string text) {
  const auto not_space = [](unsigned char c) { return !std::isspace(c); };
  text.erase(text.begin(), std::find_if(text.begin(), text.end(), not_space));
  text.erase(std::find_if(text.rbegin(), text.rend(), not_space).base(), text.end());
  return text;
}

std::string Lower(std::string text) {
  for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

std::optional<int> ParsePositive(const std::string& text) {
  int value = 0;
  const auto result = std::from_chars(text.data(), text.data() + text.size(), value);
  if (result.ec != std::errc() || result.ptr != text.data() + text.size() || value <= 0 ||
      value > 65535) {
    return std::nullopt;
  }
  return value;
}

// Sensor sizes of Prophesee sensor generations, for headers that do not state one.
std::optional<SensorSize> SizeOfSensorGeneration(const std::string& text) {
  const std::string lower = Lower(text);
  if (lower.find("imx636") != std::string::npos || lower.find("gen4") != std::string::npos ||
      lower.find("4.1") != std::string::npos || lower == "4" || lower == "4.0") {
    return SensorSize{1280, 720};
  }
  if (lower.find("genx320") != std::string::npos) {
    return SensorSize{320, 320};
  }
  if (lower.find("gen3") != std::string::npos || lower == "3" || lower == "3.0" || lower == "3.1") {
    return SensorSize{640, 480};
  }
  return std::nullopt;
}

}  // namespace

PropheseeRawHeader ReadPropheseeRawHeader(std::istream& stream, const std::string& source) {
  PropheseeRawHeader header;
  std::optional<PropheseeEncoding> encoding;
  std::optional<SensorSize> format_size, geometry_size, generation_size;
  while (true) {
    // A header line starts with "% "; the payload may legitimately start with '%' (0x25).
    const int first = stream.peek();
    if (first != '%') break;
    stream.get();
    const int second = stream.peek();
    if (second != ' ' && second != '\n') {
      stream.unget();
      break;
    }
    std::string line;
    int c;
    while ((c = stream.get()) != std::char_traits<char>::eof() && c != '\n') {
      if (line.size() >= kMaxHeaderLine || (c < 0x20 && c != '\t' && c != '\r')) {
        throw ParseError::AtByte(source, header.size_bytes,
                                 "malformed header line (binary data or longer than " +
                                     std::to_string(kMaxHeaderLine) + " bytes)");
      }
      line.push_back(static_cast<char>(c));
    }
    const uint64_t line_start = header.size_bytes;
    header.size_bytes += 1 + line.size() + (c == '\n' ? 1 : 0);
    line = Trim(line);
    const size_t space = line.find_first_of(" \t");
    const std::string key = line.substr(0, space);
    const std::string value = space == std::string::npos ? "" : Trim(line.substr(space));
    header.fields.emplace_back(key, value);
    if (key == "end") break;
    if (key == "evt") {
      if (value == "3.0" || value == "3") {
        encoding = PropheseeEncoding::kEvt3;
      } else if (value == "2.0" || value == "2") {
        encoding = PropheseeEncoding::kEvt2;
      } else {
        throw ParseError::AtByte(
            source, line_start,
            "unsupported event encoding 'evt " + value + "' (evloc decodes EVT 2.0 and EVT 3.0)");
      }
    } else if (key == "format") {
      // e.g. "EVT3;height=720;width=1280".
      std::vector<std::string> parts;
      size_t begin = 0;
      while (begin <= value.size()) {
        const size_t end = std::min(value.find(';', begin), value.size());
        parts.push_back(Trim(value.substr(begin, end - begin)));
        begin = end + 1;
      }
      const std::string name = Lower(parts.front());
      if (name == "evt3" || name == "evt3.0") {
        encoding = PropheseeEncoding::kEvt3;
      } else if (name == "evt2" || name == "evt2.0") {
        encoding = PropheseeEncoding::kEvt2;
      } else {
        throw ParseError::AtByte(
            source, line_start,
            "unsupported event format '" + parts.front() + "' (evloc decodes EVT2 and EVT3)");
      }
      std::optional<int> width, height;
      for (const std::string& part : parts) {
        if (part.rfind("width=", 0) == 0) width = ParsePositive(part.substr(6));
        if (part.rfind("height=", 0) == 0) height = ParsePositive(part.substr(7));
      }
      if (width && height) format_size = SensorSize{*width, *height};
    } else if (key == "geometry") {
      const size_t x = value.find('x');
      if (x != std::string::npos) {
        const auto width = ParsePositive(value.substr(0, x));
        const auto height = ParsePositive(value.substr(x + 1));
        if (width && height) geometry_size = SensorSize{*width, *height};
      }
    } else if (key == "plugin_name" || key == "sensor_generation") {
      if (const auto size = SizeOfSensorGeneration(value)) generation_size = size;
    }
  }
  if (!encoding) {
    throw ParseError::AtByte(source, header.size_bytes,
                             "no '% evt 2.0|3.0' or '% format EVT2|EVT3' header line: cannot "
                             "tell the payload encoding");
  }
  header.encoding = *encoding;
  if (format_size) {
    header.sensor_size = format_size;
  } else if (geometry_size) {
    header.sensor_size = geometry_size;
  } else if (generation_size) {
    header.sensor_size = generation_size;
    header.sensor_size_inferred = true;
  }
  return header;
}

PropheseeRawReader::PropheseeRawReader(const std::filesystem::path& path)
    : stream_(std::make_unique<std::ifstream>(path, std::ios::binary)), source_(path.string()) {
  if (!*stream_) throw IoError(source_ + ": cannot open");
  Initialise();
}

PropheseeRawReader::PropheseeRawReader(std::unique_ptr<std::istream> stream, std::string source)
    : stream_(std::move(stream)), source_(std::move(source)) {
  if (!stream_) throw InvalidArgumentError("PropheseeRawReader: null stream");
  Initialise();
}

void PropheseeRawReader::Initialise() {
  header_ = ReadPropheseeRawHeader(*stream_, source_);
  PropheseeDecoderOptions options;
  options.sensor_size = header_.sensor_size;
  options.source = source_;
  options.first_byte_offset = header_.size_bytes;
  if (header_.encoding == PropheseeEncoding::kEvt3) {
    decoder_ = std::make_unique<Evt3Decoder>(options);
  } else {
    decoder_ = std::make_unique<Evt2Decoder>(options);
  }
  block_.resize(kBlockSize);
}

uint64_t PropheseeRawReader::dropped_event_count() const {
  return decoder_->statistics().dropped_outside_sensor +
         decoder_->statistics().dropped_before_state;
}

size_t PropheseeRawReader::Read(size_t max_events, EventBuffer* out) {
  if (out == nullptr) throw InvalidArgumentError("PropheseeRawReader::Read: output is null");
  size_t appended = 0;
  while (appended < max_events) {
    if (pending_position_ == pending_.size()) {
      pending_.clear();
      pending_position_ = 0;
      if (end_of_stream_) break;
      stream_->read(reinterpret_cast<char*>(block_.data()),
                    static_cast<std::streamsize>(block_.size()));
      const auto got = static_cast<size_t>(stream_->gcount());
      if (stream_->bad()) throw IoError(source_ + ": read failed");
      if (got < block_.size()) end_of_stream_ = true;
      decoder_->Decode(block_.data(), got, &pending_);
      if (end_of_stream_ && decoder_->has_partial_word()) {
        throw ParseError::AtByte(source_, header_.size_bytes + decoder_->statistics().bytes,
                                 "file ends inside a word (truncated payload)");
      }
      continue;
    }
    const size_t count = std::min(max_events - appended, pending_.size() - pending_position_);
    out->Append(pending_, pending_position_, count);
    pending_position_ += count;
    appended += count;
  }
  return appended;
}

}  // namespace evloc
