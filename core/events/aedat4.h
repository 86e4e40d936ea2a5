// iniVation DV AEDAT 4.0 files: the header, the stream table of its XML description, packets
// read one at a time (uncompressed, LZ4 or Zstd), and the decoders of the four packet types DV
// records: events (EVTS), frames (FRME), IMU samples (IMUS) and triggers (TRIG)
// (docs/event-formats.md, section 8). The flatbuffers schemas are core/events/aedat4_schema.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <istream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/events/event.h"
#include "core/events/event_reader.h"

namespace evloc {

// The default events stream (DV's capture module names its outputs events, frames, imu,
// triggers).
inline constexpr char kDefaultAedat4EventsStream[] = "events";
// The default frames stream.
inline constexpr char kDefaultAedat4FramesStream[] = "frames";

// The compression of an AEDAT4 file's packets (IOHeader.compression).
enum class Aedat4Compression { kNone = 0, kLz4 = 1, kLz4High = 2, kZstd = 3, kZstdHigh = 4 };

// "none", "lz4", "lz4-high", "zstd", "zstd-high".
const char* Aedat4CompressionName(Aedat4Compression compression);

// One stream of an AEDAT4 file, from the `outInfo` node of the header's XML description.
struct Aedat4Stream {
  // The id the packet headers refer to.
  int32_t id = 0;
  // The output's name (`originalOutputName`, e.g. "events"); the id as text when absent.
  std::string name;
  // The flatbuffers type identifier: EVTS, FRME, IMUS, TRIG (others are listed, never decoded).
  std::string type;
  // The producing module (`originalModuleName`, e.g. "capture"), may be empty.
  std::string module;
  // The camera (`info/source`, e.g. "DAVIS346_00000499"), may be empty.
  std::string camera;
  // The sensor size (`info/sizeX`, `info/sizeY`) when stated (events and frames streams).
  std::optional<SensorSize> size;
};

// A packet of an AEDAT4 file. `data` points into the reader's buffer and stays valid until the
// next call of Aedat4Reader::Next(): the decompressed body, a size-prefixed flatbuffer whose
// file identifier matched the stream's type and whose tables passed flatbuffers' verifier.
struct Aedat4Packet {
  // The packet's stream.
  const Aedat4Stream* stream = nullptr;
  // File byte of the packet header (stream id, size).
  uint64_t file_offset = 0;
  // The decompressed body.
  const uint8_t* data = nullptr;
  // Its size in bytes.
  size_t size = 0;
  // The file's compression (offsets in `data` are then in the decompressed bytes).
  Aedat4Compression compression = Aedat4Compression::kNone;
};

// Names a position in a packet for ParseError: the file byte for an uncompressed file, else the
// byte of the decompressed body and the packet's file byte.
std::string Aedat4Position(const Aedat4Packet& packet, uint64_t offset_in_body);

// True when `path` starts with the AEDAT 4.0 magic "#!AER-DAT4.0\r\n". Throws IoError when it
// cannot be read.
bool IsAedat4File(const std::filesystem::path& path);

// Streams the packets of an AEDAT4 file in file order, one packet in memory at a time. Every
// malformed or truncated structure is a ParseError naming the source, the byte offset and what
// was expected.
class Aedat4Reader {
 public:
  // Largest decompressed packet accepted (DV writes packets of a few hundred KiB).
  static constexpr uint64_t kMaxPacketBytes = uint64_t{256} << 20;
  // Largest IOHeader accepted.
  static constexpr uint64_t kMaxHeaderBytes = uint64_t{16} << 20;

  // Opens `path` and reads the header and its stream table. Throws IoError when it cannot be
  // opened, ParseError when it is not a valid AEDAT4 file.
  explicit Aedat4Reader(const std::filesystem::path& path);
  // Reads from a seekable `stream`; `source` names it in error messages.
  Aedat4Reader(std::unique_ptr<std::istream> stream, std::string source);
  ~Aedat4Reader();
  Aedat4Reader(const Aedat4Reader&) = delete;
  Aedat4Reader& operator=(const Aedat4Reader&) = delete;

  // Every stream of the file, in the header's order.
  const std::vector<Aedat4Stream>& streams() const { return streams_; }
  // The stream named `name_or_id` (its name, or its id as decimal text); nullptr when absent.
  const Aedat4Stream* FindStream(const std::string& name_or_id) const;
  // The streams as "name (id N, TYPE)", in id order, for error messages.
  std::string DescribeStreams() const;
  // The packets' compression.
  Aedat4Compression compression() const { return compression_; }
  // The source name used in errors.
  const std::string& source() const { return source_; }
  // The XML description of the streams, as stored.
  const std::string& description() const { return description_; }

  // Restricts Next() to packets of these stream ids (empty: all streams). Call before Next().
  void SetStreams(const std::vector<int32_t>& ids);
  // Reads the next packet of the selected streams; false at the end of the packets (the file's
  // end, or the file data table when the header gives its position; the table is then checked
  // to be complete and well-formed, not used).
  bool Next(Aedat4Packet* packet);

 private:
  struct Decompressor;
  void Open();
  void ReadAt(uint64_t offset, void* data, size_t size, const char* what);
  // Decompresses compressed_ into body_ (body_size_); `offset` and `what` name it in errors.
  void Decompress(uint64_t offset, const char* what);
  void VerifyBody(const Aedat4Packet& packet) const;
  // Checks the file data table at packets_end_: complete and well-formed.
  void VerifyDataTable();

  std::unique_ptr<std::istream> stream_;
  std::string source_;
  uint64_t file_size_ = 0;
  uint64_t packets_end_ = 0;
  Aedat4Compression compression_ = Aedat4Compression::kNone;
  std::string description_;
  std::vector<Aedat4Stream> streams_;
  std::vector<int32_t> selected_;
  bool table_checked_ = false;
  // File position of the next packet header.
  uint64_t position_ = 0;
  std::vector<uint8_t> compressed_;
  std::vector<uint8_t> body_;
  size_t body_size_ = 0;
  std::unique_ptr<Decompressor> decompressor_;
};

// Decodes the events of an EVTS packet and appends them to `out` (times µs → ns, polarity
// true → +1). Events outside `bounds` (when given) or at negative coordinates are dropped and
// counted in `*dropped`. Throws ParseError for a time beyond ±2^63 ns.
void DecodeAedat4Events(const Aedat4Packet& packet, const std::string& source,
                        const std::optional<SensorSize>& bounds, EventBuffer* out,
                        uint64_t* dropped);

// A decoded FRME packet.
struct Aedat4Frame {
  // The frame's time (DV: the start of its exposure), nanoseconds.
  int64_t t_ns = 0;
  // Start and end of the exposure, nanoseconds.
  int64_t exposure_begin_ns = 0;
  // End of the exposure.
  int64_t exposure_end_ns = 0;
  // Size in pixels.
  int width = 0;
  // Height in pixels.
  int height = 0;
  // Position of the frame's top-left pixel on the sensor.
  int position_x = 0;
  // Its row.
  int position_y = 0;
  // Channels: 1 (gray), 3 (BGR) or 4 (BGRA).
  int channels = 1;
  // Bytes per channel: 1 or 2 (16-bit gray).
  int bytes_per_channel = 1;
  // Row-major pixels, width × height × channels × bytes_per_channel bytes (little-endian).
  std::vector<uint8_t> pixels;
};

// Decodes a FRME packet. Throws ParseError for an unknown format or a pixel count that does
// not match the size.
Aedat4Frame DecodeAedat4Frame(const Aedat4Packet& packet, const std::string& source);

// One IMU sample (units as DV records them).
struct Aedat4ImuSample {
  // Time, nanoseconds.
  int64_t t_ns = 0;
  // Temperature, degrees Celsius.
  float temperature_c = 0;
  // Acceleration x, y, z, g.
  float accelerometer_g[3] = {0, 0, 0};
  // Angular velocity x, y, z, degrees per second.
  float gyroscope_dps[3] = {0, 0, 0};
  // Magnetic field x, y, z, microtesla.
  float magnetometer_ut[3] = {0, 0, 0};
};

// Decodes an IMUS packet and appends its samples to `out`.
void DecodeAedat4Imu(const Aedat4Packet& packet, const std::string& source,
                     std::vector<Aedat4ImuSample>* out);

// One trigger.
struct Aedat4Trigger {
  // Time, nanoseconds.
  int64_t t_ns = 0;
  // DV's TriggerType: 0 timestamp reset, 1..5 external signal or generator edges and pulses,
  // 6..9 frame and exposure begin and end.
  int type = 0;
};

// Decodes a TRIG packet and appends its triggers to `out`.
void DecodeAedat4Triggers(const Aedat4Packet& packet, const std::string& source,
                          std::vector<Aedat4Trigger>* out);

// Options of the AEDAT4 event reader.
struct Aedat4EventOptions {
  // The stream holding the events: its name or its id.
  std::string stream = kDefaultAedat4EventsStream;

  // Throws InvalidArgumentError when the stream is empty.
  void Check() const;
};

// Streams the events of one stream of an AEDAT4 file, packet by packet.
class Aedat4EventReader final : public PacketEventReader {
 public:
  // Opens the file. Throws IoError / ParseError for the file, InvalidArgumentError when the
  // stream is missing (the message lists the file's streams) or is not an events stream.
  Aedat4EventReader(const std::filesystem::path& path, const Aedat4EventOptions& options = {});
  // Reads from a seekable stream; `source` names it in errors.
  Aedat4EventReader(std::unique_ptr<std::istream> stream, std::string source,
                    const Aedat4EventOptions& options = {});

  // The stream's sizeX × sizeY from the header, when stated.
  std::optional<SensorSize> sensor_size() const override { return sensor_size_; }
  uint64_t dropped_event_count() const override { return dropped_; }

  // The file underneath (streams).
  const Aedat4Reader& file() const { return *file_; }
  // Packets decoded so far.
  uint64_t packets() const { return packets_; }

 private:
  void Initialise(const Aedat4EventOptions& options);
  // Appends the next packet's events to `out`; false at the end.
  bool DecodeNextPacket(EventBuffer* out) override;

  std::unique_ptr<Aedat4Reader> file_;
  std::optional<SensorSize> sensor_size_;
  uint64_t dropped_ = 0;
  uint64_t packets_ = 0;
};

// The streams of `reader` whose type is `type` (EVTS, FRME, IMUS, TRIG).
std::vector<const Aedat4Stream*> Aedat4StreamsOfType(const Aedat4Reader& reader,
                                                     const std::string& type);

}  // namespace evloc
