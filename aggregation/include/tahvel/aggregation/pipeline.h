// The HRV chain as one function: ECG samples -> R peaks -> RR intervals with the NN mask (the
// RR-only rule) -> HRV for the whole series and per window. `tahvel hrv` and the whiteboard
// agents both run it, so the same record gives the same metrics whichever way it goes.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "tahvel/aggregation/error.h"
#include "tahvel/aggregation/hrv.h"
#include "tahvel/aggregation/rpeak.h"
#include "tahvel/aggregation/rr.h"

namespace tahvel::aggregation {

struct ChainOptions {
  DetectorOptions detector;  // fs and gain are taken from the record or the caller
  NnRule nn;
  HrvOptions hrv;
  double window_s = 300;     // HRV windows (Task Force short-term: 5 min)
  double step_s = 0;         // 0: the window length (windows do not overlap)
};

struct HrvReport {
  double fs = 0;
  std::vector<std::int64_t> beats;   // detected R peaks, sample indices
  std::vector<Interval> intervals;   // consecutive beats, NN-marked
  HrvMetrics metrics;                // the whole series
  std::vector<WindowMetrics> windows;
};

// The chain over one lead sampled at fs Hz with `gain` ADC units per mV. Errors: invalid
// detector options or window settings (the message names the option).
Result<HrvReport> hrv_from_samples(const std::vector<std::int32_t>& samples, double fs,
                                   double gain, const ChainOptions& options = {});

// The chain over signal `channel` (0: the first, MLII in MIT-BIH) of a WFDB record given
// without extension. Errors: those of read_signals, and a channel the record does not have.
Result<HrvReport> hrv_from_record(const std::string& record_path, const ChainOptions& options = {},
                                  std::size_t channel = 0);

}  // namespace tahvel::aggregation
