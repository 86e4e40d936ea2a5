// Decoding and reading throughput of the event formats, in million events per second on one
// core (counter "Mev/s"). Results and the command line are in docs/benchmarks.md.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

#include "core/events/aedat4.h"
#include "core/events/ecd_text.h"
#include "core/events/evb.h"
#include "core/events/event.h"
#include "core/events/prophesee_decoder.h"
#include "core/events/rosbag_events.h"

namespace evloc {
namespace {

// The shared real-data folder: $EVLOC_DATA_DIR, else ../shared/data beside the source tree.
std::filesystem::path SharedDataDir() {
  if (const char* from_environment = std::getenv("EVLOC_DATA_DIR")) return from_environment;
  return std::filesystem::path(EVLOC_SOURCE_DIR) / ".." / "shared" / "data";
}

// The payload of a Prophesee .raw file (after its `% ` header lines); empty if absent.
std::vector<uint8_t> RawPayload(const std::filesystem::path& path) {
  std::ifstream file(path, std::ios::binary);
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(file)),
                             std::istreambuf_iterator<char>());
  size_t offset = 0;
  while (offset + 1 < bytes.size() && bytes[offset] == '%' && bytes[offset + 1] == ' ') {
    while (offset < bytes.size() && bytes[offset] != '\n') ++offset;
    ++offset;
  }
  return {bytes.begin() + static_cast<std::ptrdiff_t>(std::min(offset, bytes.size())), bytes.end()};
}

// `payload` repeated until it is at least `min_bytes` long (whole words only).
std::vector<uint8_t> Replicate(const std::vector<uint8_t>& payload, size_t word_size,
                               size_t min_bytes) {
  std::vector<uint8_t> bytes;
  const size_t whole = payload.size() / word_size * word_size;
  while (bytes.size() < min_bytes)
    bytes.insert(bytes.end(), payload.begin(), payload.begin() + whole);
  return bytes;
}

// Decodes `bytes` in 64 KiB packets per iteration and reports events per second.
template <typename Decoder>
void DecodeBenchmark(benchmark::State& state, const std::vector<uint8_t>& bytes) {
  constexpr size_t kPacket = 1 << 16;
  EventBuffer events;
  events.reserve(kPacket * 8);
  uint64_t total = 0;
  for (auto _ : state) {
    Decoder decoder;
    for (size_t offset = 0; offset < bytes.size(); offset += kPacket) {
      events.clear();
      decoder.Decode(bytes.data() + offset, std::min(kPacket, bytes.size() - offset), &events);
      benchmark::DoNotOptimize(events.t_ns.data());
    }
    total += decoder.statistics().events;
  }
  state.counters["Mev/s"] =
      benchmark::Counter(static_cast<double>(total) / 1e6, benchmark::Counter::kIsRate);
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * bytes.size()));
}

void BM_Evt3DecodeRealSample(benchmark::State& state) {
  const auto payload = RawPayload(SharedDataDir() / "prophesee" / "evt3_sample.raw");
  if (payload.empty()) {
    state.SkipWithError("shared data prophesee/evt3_sample.raw absent (set EVLOC_DATA_DIR)");
    return;
  }
  DecodeBenchmark<Evt3Decoder>(state, Replicate(payload, 2, 32 << 20));
}
BENCHMARK(BM_Evt3DecodeRealSample)->Unit(benchmark::kMillisecond);

// A dense synthetic EVT 3.0 stream: every row gets a VECT_BASE_X, two full VECT_12 and a
// VECT_8 (32 events), plus single events; a new EVT_TIME_LOW every row.
void BM_Evt3DecodeSyntheticDense(benchmark::State& state) {
  std::vector<uint16_t> words;
  for (uint32_t step = 0; words.size() < (16u << 20); ++step) {
    if (step % 4096 == 0) words.push_back(static_cast<uint16_t>(0x8000 | ((step >> 12) & 0xFFF)));
    words.push_back(static_cast<uint16_t>(0x6000 | (step & 0xFFF)));
    words.push_back(static_cast<uint16_t>(0x0000 | (step % 720)));
    words.push_back(static_cast<uint16_t>(0x3000 | ((step & 1) << 11) | (step * 7 % 1200)));
    words.push_back(0x4FFF);
    words.push_back(0x4A5A);
    words.push_back(0x50FF);
    words.push_back(static_cast<uint16_t>(0x2800 | (step * 13 % 1280)));
  }
  std::vector<uint8_t> bytes(words.size() * 2);
  std::memcpy(bytes.data(), words.data(), bytes.size());
  DecodeBenchmark<Evt3Decoder>(state, bytes);
}
BENCHMARK(BM_Evt3DecodeSyntheticDense)->Unit(benchmark::kMillisecond);

void BM_Evt2DecodeRealSample(benchmark::State& state) {
  const auto payload = RawPayload(SharedDataDir() / "prophesee" / "evt2_sample.raw");
  if (payload.empty()) {
    state.SkipWithError("shared data prophesee/evt2_sample.raw absent (set EVLOC_DATA_DIR)");
    return;
  }
  DecodeBenchmark<Evt2Decoder>(state, Replicate(payload, 4, 64 << 20));
}
BENCHMARK(BM_Evt2DecodeRealSample)->Unit(benchmark::kMillisecond);

// Events in the style of a DAVIS240 recording.
EventBuffer SyntheticEvents(size_t count) {
  EventBuffer events;
  events.reserve(count);
  int64_t t_ns = 49'006'624'000;
  for (size_t i = 0; i < count; ++i) {
    t_ns += static_cast<int64_t>((i * 2654435761u) % 3000);
    events.push_back({t_ns, static_cast<uint16_t>(i * 31 % 240),
                      static_cast<uint16_t>(i * 17 % 180), (i * 7 % 3) ? int8_t{1} : int8_t{-1}});
  }
  return events;
}

void BM_EcdTextRead(benchmark::State& state) {
  const auto directory = std::filesystem::temp_directory_path() / "evloc-events-benchmark";
  std::filesystem::create_directories(directory);
  const auto path = directory / "events.txt";
  const EventBuffer events = SyntheticEvents(1 << 20);
  {
    EcdTextWriter writer(path);
    writer.Write(events);
    writer.Close();
  }
  uint64_t total = 0;
  EventBuffer read;
  for (auto _ : state) {
    EcdTextReader reader(path);
    read.clear();
    while (reader.Read(1 << 16, &read) > 0) {
    }
    total += read.size();
  }
  state.counters["Mev/s"] =
      benchmark::Counter(static_cast<double>(total) / 1e6, benchmark::Counter::kIsRate);
  std::filesystem::remove_all(directory);
}
BENCHMARK(BM_EcdTextRead)->Unit(benchmark::kMillisecond);

void BM_EvbRead(benchmark::State& state) {
  const auto directory = std::filesystem::temp_directory_path() / "evloc-events-benchmark-evb";
  std::filesystem::create_directories(directory);
  const auto path = directory / "events.evb";
  const EventBuffer events = SyntheticEvents(4 << 20);
  {
    EvbWriter writer(path, SensorSize{240, 180});
    writer.Write(events);
    writer.Close();
  }
  uint64_t total = 0;
  EventBuffer read;
  for (auto _ : state) {
    EvbReader reader(path);
    read.clear();
    while (reader.Read(1 << 16, &read) > 0) {
    }
    total += read.size();
  }
  state.counters["Mev/s"] =
      benchmark::Counter(static_cast<double>(total) / 1e6, benchmark::Counter::kIsRate);
  std::filesystem::remove_all(directory);
}
BENCHMARK(BM_EvbRead)->Unit(benchmark::kMillisecond);

// Runs `script` (a test-file writer of core/events/testing) with `--bench 2^22 FOLDER` into a
// fresh temporary folder; the folder, or empty when the script fails.
std::filesystem::path WriteBenchFiles(const char* script, const char* folder_name,
                                      const std::string& extra_arguments = "") {
  const auto folder = std::filesystem::temp_directory_path() / folder_name;
  std::filesystem::remove_all(folder);
  std::filesystem::create_directories(folder);
  const auto path =
      std::filesystem::path(EVLOC_SOURCE_DIR) / "core" / "events" / "testing" / script;
  const std::string command = "/usr/bin/python3 '" + path.string() + "' --bench " +
                              std::to_string(4 << 20) + " '" + folder.string() + "'" +
                              extra_arguments;
  return std::system(command.c_str()) == 0 ? folder : std::filesystem::path();
}

// The dvs_msgs bags of 2^22 events (messages of 1,000) written by Debian's python3-rosbag with
// core/events/testing/write_test_bags.py --bench, once per process; empty when it cannot run.
std::filesystem::path BenchBagsDir() {
  static const std::filesystem::path dir =
      WriteBenchFiles("write_test_bags.py", "evloc-events-benchmark-bags");
  return dir;
}

// The AEDAT4 files of 2^22 events (packets of 10,000) written with python3-flatbuffers,
// python3-lz4 and python3-zstandard by write_test_aedat4.py --bench, once per process: uniformly
// random DAVIS346 pixels (bench_*), and the real DAVIS240 events of the shared ECD snippets
// repeated (bench_ecd_*, only when the shared data is present).
std::filesystem::path BenchAedat4Dir() {
  static const std::filesystem::path dir = [] {
    std::string snippets;
    const auto folder = SharedDataDir() / "ecd" / "snippets";
    if (std::filesystem::is_directory(folder)) {
      std::vector<std::string> files;
      for (const auto& entry : std::filesystem::directory_iterator(folder)) {
        if (std::filesystem::exists(entry.path() / "events.txt")) {
          files.push_back((entry.path() / "events.txt").string());
        }
      }
      std::sort(files.begin(), files.end());
      for (const std::string& file : files) snippets += " '" + file + "'";
    }
    return WriteBenchFiles("write_test_aedat4.py", "evloc-events-benchmark-aedat4", snippets);
  }();
  return dir;
}

// Reads the 2^22 events of `path` with a Reader in 2^16-event calls, opening it every iteration.
template <typename Reader>
void ReadRecording(benchmark::State& state, const std::filesystem::path& dir,
                   const std::string& file, const char* writer) {
  if (dir.empty()) {
    state.SkipWithError(
        (std::string(writer) + " --bench failed (see scripts/install-deps.sh)").c_str());
    return;
  }
  const auto path = dir / file;
  uint64_t total = 0;
  EventBuffer read;
  for (auto _ : state) {
    Reader reader(path);
    read.clear();
    while (reader.Read(1 << 16, &read) > 0) {
    }
    if (read.size() != (4u << 20)) {
      state.SkipWithError("the bench file does not hold 2^22 events");
      return;
    }
    total += read.size();
  }
  state.counters["Mev/s"] =
      benchmark::Counter(static_cast<double>(total) / 1e6, benchmark::Counter::kIsRate);
}

// Reads the events of a dvs_msgs/EventArray bag (`compression` none or lz4).
void RosbagDvsRead(benchmark::State& state, const char* compression) {
  ReadRecording<RosbagEventReader>(
      state, BenchBagsDir(), std::string("bench_") + compression + ".bag", "write_test_bags.py");
}

void BM_RosbagDvsReadUncompressed(benchmark::State& state) { RosbagDvsRead(state, "none"); }
BENCHMARK(BM_RosbagDvsReadUncompressed)->Unit(benchmark::kMillisecond);

void BM_RosbagDvsReadLz4(benchmark::State& state) { RosbagDvsRead(state, "lz4"); }
BENCHMARK(BM_RosbagDvsReadLz4)->Unit(benchmark::kMillisecond);

// Reads the events stream of an AEDAT4 file (`compression` none, lz4 or zstd).
void Aedat4Read(benchmark::State& state, const char* compression) {
  ReadRecording<Aedat4EventReader>(state, BenchAedat4Dir(),
                                   std::string("bench_") + compression + ".aedat4",
                                   "write_test_aedat4.py");
}

void BM_Aedat4ReadUncompressed(benchmark::State& state) { Aedat4Read(state, "none"); }
BENCHMARK(BM_Aedat4ReadUncompressed)->Unit(benchmark::kMillisecond);

void BM_Aedat4ReadLz4(benchmark::State& state) { Aedat4Read(state, "lz4"); }
BENCHMARK(BM_Aedat4ReadLz4)->Unit(benchmark::kMillisecond);

void BM_Aedat4ReadZstd(benchmark::State& state) { Aedat4Read(state, "zstd"); }
BENCHMARK(BM_Aedat4ReadZstd)->Unit(benchmark::kMillisecond);

// The same three compressions for the repeated real ECD events.
void Aedat4EcdRead(benchmark::State& state, const char* compression) {
  const auto file = std::string("bench_ecd_") + compression + ".aedat4";
  if (!BenchAedat4Dir().empty() && !std::filesystem::exists(BenchAedat4Dir() / file)) {
    state.SkipWithError("the shared ECD snippets are absent (../shared/data or EVLOC_DATA_DIR)");
    return;
  }
  ReadRecording<Aedat4EventReader>(state, BenchAedat4Dir(), file, "write_test_aedat4.py");
}

void BM_Aedat4EcdReadUncompressed(benchmark::State& state) { Aedat4EcdRead(state, "none"); }
BENCHMARK(BM_Aedat4EcdReadUncompressed)->Unit(benchmark::kMillisecond);

void BM_Aedat4EcdReadLz4(benchmark::State& state) { Aedat4EcdRead(state, "lz4"); }
BENCHMARK(BM_Aedat4EcdReadLz4)->Unit(benchmark::kMillisecond);

void BM_Aedat4EcdReadZstd(benchmark::State& state) { Aedat4EcdRead(state, "zstd"); }
BENCHMARK(BM_Aedat4EcdReadZstd)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace evloc

BENCHMARK_MAIN();
