// WFDB record input: the text header (.hea) and the signal files (.dat) of a PhysioNet record,
// read without the WFDB library. Tuned for MIT-BIH-sized records (two signals, 650,000 frames,
// 1.9 MB): read_signals() holds a whole record in memory; SignalReader replays one in chunks
// (agents replay 1-second chunks) and holds only the chunk.
//
// Supported: single-segment records; the signal formats of WFDB's signal(5) without
// compression (8, 16, 24, 32, 61, 80, 160, 212, 310, 311); several signals per file
// (interleaved) and several files per record; a byte offset before the first sample. Anything
// else (multi-segment records, other formats, more than one sample per frame, skew) is refused
// with an Error naming the header file, line and field. Nothing is ever read short silently:
// a signal file that ends before the header's sample count is an Error that names the file and
// the expected and found sample counts.
//
// Specification followed: the WFDB header format (PhysioNet "header(5)") and signal formats
// ("signal(5)"); see docs/wfdb.md.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "tahvel/aggregation/error.h"

namespace tahvel::aggregation {

// One signal line of a header.
struct SignalInfo {
  std::string file;          // signal file name as written in the header, relative to the header's
                             // directory ("100.dat")
  int format = 0;            // storage format: 8, 16, 24, 32, 61, 80, 160, 212, 310 or 311
  double gain = 200;         // ADC units per physical unit; 0 or absent in the header means 200;
                             // negative for a lead recorded upside down
  int baseline = 0;          // ADC value of physical zero; absent means adc_zero
  std::string units = "mV";  // physical units; absent means "mV"
  int adc_resolution = 0;    // bits; absent or 0 means the format's (8, 10, 12, 16, 24 or 32)
  int adc_zero = 0;          // ADC value at the middle of the input range; absent means 0
  int initial_value = 0;     // first sample (format 8: what its first difference adds to);
                             // absent means adc_zero
  int checksum = 0;          // 16-bit sum of all samples as written (0 when absent)
  bool has_checksum = false;  // whether the header gave a checksum
  int block_size = 0;        // 0 for ordinary files
  std::int64_t byte_offset = 0;  // bytes to skip at the start of the file ("212+12")
  std::string description;   // rest of the line ("MLII"); may be empty or contain spaces
};

// The highest sampling frequency a header may give: readers and the R-peak detector size
// buffers by seconds of signal, and a rate of 1e9 in a header took all the memory there is.
// High-resolution ECG is sampled at up to tens of kHz.
inline constexpr double kMaxSamplingHz = 100'000;

// A parsed header. samples_per_signal is 0 when the header does not give it (then the signal
// files are read to their end).
struct RecordHeader {
  std::string name;        // record name from the record line ("100")
  int signal_count = 0;
  double fs = 250;         // samples per second per signal; absent means 250 (the WFDB default)
  bool fs_given = false;   // whether the record line gives it
  std::int64_t samples_per_signal = 0;
  std::vector<SignalInfo> signals;
  std::string directory;   // directory of the .hea file; signal files are opened relative to it
  std::string path;        // the .hea file read ("<record_path>.hea"), for messages
  std::vector<std::string> comments;  // '#' lines, without the '#' and surrounding blanks
};

// Reads and parses "<record_path>.hea". record_path is the record without extension
// ("…/mitdb/100"). Accepts LF and CRLF line endings, '#' comment lines and blank lines.
// Errors: the file cannot be opened; no record line; a field that does not parse (message
// "<file>:<line>: field '<name>' ..."); fewer signal lines than the record line announces;
// a multi-segment record; an unsupported format, more than one sample per frame or a skew.
Result<RecordHeader> read_header(const std::string& record_path);

// All samples of a record, raw ADC units, one vector per signal (in header order), each of
// header.samples_per_signal values (or as many whole frames as the files hold when the header
// gives no count).
struct Signals {
  RecordHeader header;
  std::vector<std::vector<std::int32_t>> samples;
};

// Reads the header and every signal file of a record. Errors: those of read_header(); a signal
// file that cannot be opened; a signal file shorter than the header says ("<file>: truncated:
// expected N samples per signal, found M"). Bytes after the last announced sample are not read
// (unread_samples names them).
Result<Signals> read_signals(const std::string& record_path);

// One line per signal whose samples do not add up to the header's checksum (16-bit sum): the
// file is not in the format the header says, or it changed after the header was written.
// WFDB's tools warn so and read on; so does `tahvel hrv`. Empty when all agree or the header
// gives no checksums.
std::vector<std::string> checksum_mismatches(const Signals& signals);
// The same from each signal's 16-bit sum of samples (`sums`, in header order), for a reader
// that streams the record (the ECG source) and keeps sums as it goes.
std::vector<std::string> checksum_mismatches(const RecordHeader& header, const std::vector<std::uint16_t>& sums);

// One line per signal file that holds more samples per signal than the header says: they are
// not read (as WFDB's tools do not), and a header whose sample count was cut short otherwise
// shows only as checksum mismatches, which read as a wrong format. Empty when none does, or
// the header gives no sample count.
std::vector<std::string> unread_samples(const RecordHeader& header);

// A header without a sampling frequency is read at WFDB's default of 250 Hz, as WFDB's tools
// read it; a record sampled at another rate then gives heart rates and HRV off by the ratio
// (MIT-BIH 100 at 360 Hz: 52 bpm instead of 75). Said, naming the file; nullopt when given.
std::optional<std::string> default_rate_warning(const RecordHeader& header);

// The ECG lead `signal` is read as a voltage whatever its header says: a lead whose units are
// no voltage (mmHg, a typo) is read as millivolts at its gain, so a wrong header goes on
// silently. Said, naming the file, the signal and the units; nullopt for mV, uV, µV, nV and V.
std::optional<std::string> non_voltage_warning(const RecordHeader& header, std::size_t signal);

// Streaming reader: frame by frame, for agents that replay a record in chunks. Move-only; owns
// its open files and closes them in its destructor. Not thread-safe: one reader per thread.
class SignalReader {
 public:
  // Reads the header and opens the signal files. Fails as read_header() does, when a signal
  // file cannot be opened, or when a file is already shorter than the header's sample count
  // (the same "truncated" message as read_signals()).
  static Result<SignalReader> open(const std::string& record_path);

  SignalReader(SignalReader&&) noexcept;
  SignalReader& operator=(SignalReader&&) noexcept;
  SignalReader(const SignalReader&) = delete;
  SignalReader& operator=(const SignalReader&) = delete;
  ~SignalReader();

  // Appends up to `frames` frames to out: out is resized to header().signal_count vectors if it
  // has fewer, and out[i] receives signal i's samples. Returns the number of frames appended;
  // 0 at the end of the record. Errors: a file ends before the header's sample count
  // ("truncated", naming the file, expected and found counts) or a read fails. After an error
  // out holds no partial frame and further reads return the same error.
  Result<std::size_t> read(std::size_t frames, std::vector<std::vector<std::int32_t>>& out);

  const RecordHeader& header() const { return header_; }

  // Frames read so far (the sample index of the next frame).
  std::int64_t position() const { return position_; }

 private:
  struct Group;
  SignalReader() = default;
  RecordHeader header_;
  std::vector<std::unique_ptr<Group>> groups_;
  std::int64_t position_ = 0;
  std::string error_;  // sticky error after a failed read
};

// Physical value of a raw sample: (adu - baseline) / gain, in info.units. A gain of 0 is read
// as 200, the WFDB default.
double to_physical(std::int32_t adu, const SignalInfo& info);

// The sample value that WFDB writes where a signal has no value (a lead off, a gap in
// digitising): the least value of the format (-32768 in 16, 61 and 160, -2048 in 212, -512 in
// 310 and 311, -128 in 80, -2^23 in 24, -2^31 in 32). Format 8 has none; its value here is
// -2^31, which no record of 8-bit differences reaches.
std::int32_t invalid_sample(const SignalInfo& info);

// ADC units per millivolt: the header's gain is per its own unit ("1000(0)/mV" and "1(0)/uV"
// are one signal). Units other than V, mV, uV and µV are taken as they are.
double gain_per_mv(const SignalInfo& info);

// The signal the HRV chain reads when none is named: the first whose description names an ECG
// lead (ECG, EKG, MLII, V1 to V6, I, II, III, aVR, aVL, aVF, …), else the first in volts
// (V, mV, µV), else the first. In MIT-BIH it is MLII, signal 0; in a record that starts with
// respiration or blood pressure it is the ECG after it. Null signals (format 0) are passed over.
std::size_t ecg_signal(const RecordHeader& header);

// Why `signal` of `header` cannot be read as the ECG, or nullopt: a null signal (format 0, file
// "~" by convention), which SignalReader gives as WFDB's no-value at every sample.
std::optional<std::string> not_an_ecg_signal(const RecordHeader& header, std::size_t signal);

}  // namespace tahvel::aggregation
