// WFDB annotation files in the "MIT" binary format (.atr and other annotators), read without
// the WFDB library, and the two questions beat scoring and HRV ask of them: is this a beat,
// and where is the signal unreadable. A 30-minute MIT-BIH reference file (~2,000-3,500
// annotations) is read whole into memory.
//
// Format (PhysioNet "annot(5)"): a sequence of 16-bit little-endian words, each with a 6-bit
// type A in the top bits and a 10-bit field I below.
//   A = 1..49   an annotation of type A, I samples after the previous one;
//   A = 0, I>0  a "null" annotation (type 0), I samples after the previous one;
//   A = 0, I=0  end of file (required: a file that ends without it is truncated);
//   A = 59 SKIP the next 4 bytes are a signed 32-bit interval (high 16-bit word first, each
//               word little-endian) added to the running time;
//   A = 60 NUM  I is the `num` of the current and following annotations;
//   A = 61 SUB  I is the subtype of the current annotation;
//   A = 62 CHN  I is the `chan` of the current and following annotations;
//   A = 63 AUX  the low 8 bits of I are a byte count; that many bytes follow, padded to even.
// SUB, CHN, NUM and AUX words follow the annotation they modify. As in the WFDB library, `num`
// and `chan` carry over from one annotation to the next, `subtype` and `aux` do not.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "tahvel/aggregation/error.h"

namespace tahvel::aggregation {

struct Annotation {
  std::int64_t sample = 0;  // time, in samples from the start of the record
  int type = 0;             // WFDB annotation code 0..49 (ecgcodes.h): 1 = NORMAL, 14 = NOISE, ...
  char code = 0;            // ASCII mnemonic of `type` (see annotation_code()); 0 if it has none
  int subtype = 0;          // from a SUB word; 0 when absent
  int chan = 0;             // from the last CHN word; 0 before any
  int num = 0;              // from the last NUM word; 0 before any
  std::string aux;          // AUX bytes with trailing NUL bytes removed ("(N" for a rhythm change)
};

// Reads "<record_path>.<annotator>" ("…/mitdb/100" + "atr"). Annotations come in file order
// (which the WFDB writer keeps sorted by time). Types 50..58, unassigned, are read as WFDB's
// getann reads them: annotations of that type, with no mnemonic. A file whose times are in
// another unit, said by WFDB 10.5's note at time 0 ("## time resolution: F", as setafreq writes
// it), has them converted to samples at `record_fs` (rounded to the nearest), when the caller
// gives it (0: as written). Errors, each naming the file and the byte offset: the file cannot be
// opened; it ends inside a word, a SKIP interval or AUX bytes; it ends without the terminating
// zero word; a SKIP makes the time negative; a time resolution note without a frequency above 0.
Result<std::vector<Annotation>> read_annotations(const std::string& record_path,
                                                 const std::string& annotator = "atr",
                                                 double record_fs = 0);

// The mnemonic WFDB prints for an annotation code: 1 'N', 2 'L', 3 'R', 4 'a', 5 'V', 6 'F',
// 7 'J', 8 'A', 9 'S', 10 'E', 11 'j', 12 '/', 13 'Q', 14 '~', 16 '|', 18 's', 19 'T', 20 '*',
// 21 'D', 22 '"', 23 '=', 24 'p', 25 'B', 26 '^', 27 't', 28 '+', 29 'u', 30 '?', 31 '!',
// 32 '[', 33 ']', 34 'e', 35 'n', 36 '@', 37 'x', 38 'f', 39 '(', 40 ')', 41 'r'; 0 ' '.
// Codes 39 and 40 double as PQ junction and J point, which some tools print as '`' and '\'';
// annotation_type() accepts those spellings too. Other codes return 0.
char annotation_code(int type);

// The code of a mnemonic, the inverse of annotation_code(); -1 for an unknown character.
int annotation_type(char code);

// True for the beat annotations: N L R B A a J S V r F e j n E / f Q ? (WFDB's isqrs()).
// Flutter waves '!' and every rhythm, noise and waveform annotation are not beats.
bool is_beat(char code);

// Unreadable intervals, as the project's scoring convention defines them (shared/data/mitdb's
// README; MIT-BIH's own markers come in such pairs): a '~' (NOISE) annotation whose subtype has
// bits 4 and 5 set (subtype & 0x30 == 0x30) opens one; the next '~' annotation, whatever its
// subtype, closes it. An interval still open at the end runs to record_end. (bxb's getref also
// reads AHA-style files, whose single marker sits inside a short shutdown with beats after it;
// here such a marker opens an interval to the next '~' or the end.) Each pair is [first, second] in samples, both ends included, in time order.
std::vector<std::pair<std::int64_t, std::int64_t>> unreadable_intervals(
    const std::vector<Annotation>& annotations, std::int64_t record_end);

// An unreadable interval left open: its marker has no '~' after it, and `beats_after` reference
// beats follow it, which the scoring leaves out to the record's end. A file in AHA style (one
// marker inside a short shutdown) reads so; the caller says it rather than score a fraction of
// the record in silence. nullopt when every interval is closed or nothing follows.
struct UnclosedUnreadable {
  std::int64_t opened_at = 0;  // sample of the marker
  std::size_t beats_after = 0;
};
std::optional<UnclosedUnreadable> unclosed_unreadable(const std::vector<Annotation>& annotations);

// Ventricular flutter/fibrillation episodes: from each '[' (VFON) to the next ']' (VFOFF), both
// ends included; an episode still open at the end runs to record_end. bxb ignores reference
// annotations inside these and does not count unmatched detections inside them.
std::vector<std::pair<std::int64_t, std::int64_t>> flutter_intervals(
    const std::vector<Annotation>& annotations, std::int64_t record_end);

}  // namespace tahvel::aggregation
