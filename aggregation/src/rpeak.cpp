// R-peak detector: a per-sample state machine after Hamilton & Tompkins (IEEE TBME 33(12),
// 1986) and Hamilton's open-source OSEA detector, re-derived for any sampling rate. Workload:
// long single-lead streams (a 30-minute MIT-BIH record is 650,000 samples) pushed in chunks
// of any size; the per-sample path is four biquads, a running sum and a few comparisons, and
// everything heavier (medians, refinement scans) runs once per candidate peak (a few per
// second). docs/rpeak.md explains the choices and gives the MIT-BIH scores.
#include "tahvel/aggregation/rpeak.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <cstdio>
#include <complex>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <string>

namespace tahvel::aggregation {
namespace {

constexpr double kMaxDetectorHz = 100'000;  // as wfdb.h's kMaxSamplingHz

// Transposed direct form II biquad, in double: the input carries the ADC offset (~1000 adu)
// and float would lose the QRS detail of a 5 Hz high-pass under it.
struct Biquad {
  double b0 = 1, b1 = 0, b2 = 0, a1 = 0, a2 = 0;
  double z1 = 0, z2 = 0;

  double step(double x) {
    const double y = b0 * x + z1;
    z1 = b1 * x - a1 * y + z2;
    z2 = b2 * x - a2 * y;
    return y;
  }
  // The state of a filter that has had input x for ever and so puts out y (its DC gain · x):
  // started so, a filter does not ring with a signal's offset.
  void settle(double x, double y) {
    z1 = y - b0 * x;
    z2 = b2 * x - a2 * y;
  }
  std::complex<double> response(double w) const {
    const std::complex<double> z1i = std::polar(1.0, -w), z2i = std::polar(1.0, -2 * w);
    return (b0 + b1 * z1i + b2 * z2i) / (1.0 + a1 * z1i + a2 * z2i);
  }
};

// 2nd-order Butterworth sections by the bilinear transform (RBJ cookbook, Q = 1/sqrt 2).
Biquad butterworth(double fc, double fs, bool highpass) {
  const double w = 2 * std::numbers::pi * fc / fs, c = std::cos(w);
  const double alpha = std::sin(w) / std::numbers::sqrt2;
  const double a0 = 1 + alpha;
  Biquad q;
  q.b1 = (highpass ? -(1 + c) : (1 - c)) / a0;
  q.b0 = q.b2 = (highpass ? (1 + c) / 2 : (1 - c) / 2) / a0;
  q.a1 = -2 * c / a0;
  q.a2 = (1 - alpha) / a0;
  return q;
}

// A notch at f0 (RBJ cookbook), `q` = f0 / its -3 dB width; gain 1 away from it.
Biquad notch(double f0, double fs, double q) {
  const double w = 2 * std::numbers::pi * f0 / fs, cos_w = std::cos(w);
  const double alpha = std::sin(w) / (2 * q), a0 = 1 + alpha;
  Biquad n;
  n.b0 = n.b2 = 1 / a0;
  n.b1 = n.a1 = -2 * cos_w / a0;
  n.a2 = (1 - alpha) / a0;
  return n;
}

// Group delay in samples of the cascade at frequency f (numerical phase derivative).
double group_delay(const Biquad& a, const Biquad& b, double f, double fs) {
  const double w = 2 * std::numbers::pi * f / fs, dw = 1e-4;
  auto phase = [&](double x) { return std::arg(a.response(x) * b.response(x)); };
  double d = phase(w + dw) - phase(w - dw);
  if (d > std::numbers::pi) d -= 2 * std::numbers::pi;
  if (d < -std::numbers::pi) d += 2 * std::numbers::pi;
  return -d / (2 * dw);
}

double median8(std::array<double, 8> v) {
  std::sort(v.begin(), v.end());
  return (v[3] + v[4]) / 2;
}

template <class T>
void shift_in(std::array<T, 8>& buf, T value) {
  std::copy_backward(buf.begin(), buf.end() - 1, buf.end());
  buf[0] = value;
}

// The empty-gap evidence at fast rates (gap_before): the T wave has ended by this fraction of
// the interval before (by Bazett at DetectorOptions::twave_qtc, counted from the R wave: 0.53 RR
// at 150 bpm, 0.6 at 200); a missed beat lies within this many intervals of the beat before
// (sinus arrhythmia moves it by 10-15 %); the P-wave cue needs intervals of at least this
// many seconds (120 bpm).
constexpr double kTwaveRrFraction = 0.7;
constexpr double kMissedBeatLateRr = 1.2;
constexpr double kPwaveCueMinRrS = 0.5;

std::int64_t samples(double ms, double fs) {
  return std::max<std::int64_t>(1, std::llround(ms * fs / 1000));
}

}  // namespace

Result<void> validate(const DetectorOptions& o) {
  auto positive = [](double x) { return std::isfinite(x) && x > 0; };
  // 10 Hz, not std::to_string's 10.000000 Hz.
  auto number = [](double x) {
    char text[32];
    std::snprintf(text, sizeof text, "%.10g", x);
    return std::string(text);
  };
  if (!positive(o.fs)) return fail("rpeak: fs must be positive, got " + number(o.fs));
  // Its buffers hold seconds of signal: a rate of 1e9 took all the memory there is.
  if (o.fs > kMaxDetectorHz)
    return fail("rpeak: a sampling rate of " + number(o.fs) + " Hz is more than the detector takes (100000 Hz)");
  if (!(o.fs > 2 * o.lowpass_hz))
    return fail("rpeak: a sampling rate of " + number(o.fs) + " Hz is too low for R-peak detection: the QRS band it "
                "keeps ends at " + number(o.lowpass_hz) + " Hz, which needs more than twice that");
  if (!positive(std::abs(o.gain))) return fail("rpeak: gain must be a number other than 0, got " + number(o.gain));
  if (!positive(o.highpass_hz) || !(o.highpass_hz < o.lowpass_hz) || !(o.lowpass_hz < o.fs / 2))
    return fail("rpeak: need 0 < highpass_hz < lowpass_hz < fs/2, got " +
                number(o.highpass_hz) + ", " + number(o.lowpass_hz) + ", fs " +
                number(o.fs));
  if (!positive(o.integration_ms) || !positive(o.hold_ms) || !positive(o.twave_ms) ||
      !positive(o.relearn_s) || !positive(o.searchback_rr))
    return fail("rpeak: integration_ms, hold_ms, twave_ms, relearn_s, searchback_rr must be > 0");
  if (!(o.threshold_fraction > 0 && o.threshold_fraction < 1) || !(o.searchback_fraction > 0) ||
      !(o.twave_slope_ratio >= 0) || !(o.min_qrs_mv >= 0) ||
      !(o.min_qrs_fraction >= 0) || !(o.min_qrs_baseline >= 0) || !(o.empty_gap_fraction >= 0) ||
      !(o.pwave_fraction >= 0) || !std::isfinite(o.pwave_correlation) ||
      !(o.twave_qtc >= 0 && o.twave_qtc <= 1) ||
      !(o.own_pwave_ms >= 0 && o.own_pwave_ms <= 1000) || !(o.flat_run_ms >= 0 && o.flat_run_ms <= 10000))
    return fail("rpeak: threshold_fraction must be in (0,1); searchback_fraction > 0; "
                "twave_slope_ratio, min_qrs_mv, min_qrs_fraction, min_qrs_baseline, empty_gap_fraction, "
                "pwave_fraction >= 0; "
                "pwave_correlation finite; twave_qtc in [0, 1]; own_pwave_ms in [0, 1000]; flat_run_ms in [0, 10000]");
  // The history rings hold 2 s; longer windows would overrun them.
  if (!(o.relearn_s >= 1 && o.relearn_s <= 8))
    return fail("rpeak: relearn_s must be in [1, 8], got " + std::to_string(o.relearn_s));
  if (o.integration_ms > 500 || o.hold_ms > 500 || o.twave_ms > 1000)
    return fail("rpeak: integration_ms and hold_ms must be <= 500, twave_ms <= 1000");
  return {};
}

class RPeakDetector::Impl {
 public:
  explicit Impl(const DetectorOptions& o);
  void push(const std::int32_t* s, std::size_t n, std::vector<std::int64_t>& out);
  void finish(std::vector<std::int64_t>& out);
  // Where accept() appends the beats that end a confirmed empty gap (null: nowhere); set by
  // the public calls for their duration.
  std::vector<std::int64_t>* empty_gap_out_ = nullptr;
  // Where accept() appends the beats whose empty gap held a P wave (null: nowhere).
  std::vector<std::int64_t>* p_wave_gap_out_ = nullptr;
  // Beat to decision: the reported point can lie up to locate_half_ + centroid_half_ before the
  // band-passed point, which lags the QRS by the band-pass delay; the integrator peaks up to one
  // window later, is released up to 95 ms after that, then held.
  std::int64_t delay() const {
    return locate_half_ + centroid_half_ + std::llround(std::ceil(bp_delay_)) + win_ +
           fpeak_timeout_ + hold_;
  }

 private:
  // A local maximum of the integrated slope, with what classification needs.
  struct Peak {
    double height = 0;         // integrated |slope| (adu), the detection statistic
    double max_slope = 0;      // steepest band-passed slope in the QRS window (T-wave test)
    std::int64_t at = 0;       // the R wave on the original signal (fiducial()): for the
                               // detection logic (T-wave test, RR, search-back)
    std::int64_t qrs = 0;      // the band-passed QRS point, band-pass delay removed
    std::int64_t beat = 0;     // the point reported for the beat (locate()), set with the hold
    std::int64_t decided = 0;  // sample at which the hold ended
    double balance = 0;        // (R − S) / (R + S) on the original signal, for the polarity
    double p2p = 0;            // peak-to-peak of the band-passed signal in the QRS window (adu)
    bool baseline_shift = false;  // fails the baseline-shift test (decided with the hold)
  };

  void step(std::int32_t x, std::vector<std::int64_t>& out);
  void release_held(std::vector<std::int64_t>& out);
  void on_fpeak(double height, std::int64_t at);
  void note_ripple(double p2p);
  void on_candidate(const Peak& p, std::vector<std::int64_t>& out);
  void classify(const Peak& p, std::vector<std::int64_t>& out);
  void searchback(std::int64_t now, std::vector<std::int64_t>& out);
  bool gap_classified() const;
  void unfile_noise(std::int64_t at);
  void seed_noise();
  void accept(const Peak& p, std::vector<std::int64_t>& out);
  bool tick(std::int64_t now);
  void learn(std::int64_t seconds);
  bool baseline_shift(std::int64_t at) const;
  struct Gap {
    bool empty = false;   // nothing QRS-like between the beats
    bool p_wave = false;  // and a P wave was seen there (a blocked P wave)
  };
  Gap gap_before(std::int64_t at) const;
  void learn_pwave(std::int64_t beat);
  bool pwave_at(std::int64_t when, double height) const;
  double pwave_correlation(std::int64_t centre, std::int64_t stride) const;
  std::int64_t fiducial(std::int64_t qrs, double& balance) const;
  std::int64_t locate(std::int64_t qrs) const;
  void note_hum(std::int64_t qrs);
  bool dominant_positive(double up, double down) const;
  // The largest positive and negative deviations of `signal` (a ring: raw_ or notched_) over
  // [qrs - before, qrs + after], measured from the local baseline (Baseline); nullopt when the
  // window is too short or flat.
  struct Deflections {
    double up = 0, down = 0;  // both >= 0
    std::int64_t up_at = 0, down_at = 0;
  };
  std::optional<Deflections> deflections(std::int64_t qrs, std::int64_t before, std::int64_t after,
                                        const std::vector<double>& signal) const;
  double threshold() const { return noise_med_ + frac_ * (qrs_med_ - noise_med_); }
  double floor() const;
  // Sample i of one of the rings (bp_, d_, raw_, notched_).
  double at(const std::vector<double>& ring, std::int64_t i) const { return ring[static_cast<std::size_t>(i & mask_)]; }
  // The local baseline under the window [lo, hi] of a ring (raw_ or notched_): the line through
  // the mean of the window's ends with the slope of the signal from slope_half_ before to
  // slope_half_ after the window's centre, outside the QRS. A constant level (the ends' mean
  // alone) left the slope of baseline wander in the window, and the extremum and centroid
  // moved towards its higher end: up to 30 samples at 10-15 mV/s. The ends of the window
  // itself gave a worse slope: on wide complexes they lie on the QRS.
  class Baseline {
   public:
    Baseline(const std::vector<double>& ring, std::int64_t lo, std::int64_t hi, const Impl& impl)
        : centre_(static_cast<double>(lo + hi) / 2), level_((impl.at(ring, lo) + impl.at(ring, hi)) / 2) {
      const std::int64_t c = (lo + hi) / 2;
      const std::int64_t a = std::max<std::int64_t>(0, c - impl.slope_half_);
      const std::int64_t b = std::min<std::int64_t>(impl.n_ - 1, c + impl.slope_half_);
      slope_ = b > a ? (impl.at(ring, b) - impl.at(ring, a)) / static_cast<double>(b - a) : 0;
    }
    double operator()(std::int64_t i) const { return level_ + slope_ * (static_cast<double>(i) - centre_); }

   private:
    double centre_, level_, slope_ = 0;
  };
  double bp(std::int64_t i) const { return at(bp_, i); }
  double slope(std::int64_t i) const { return at(d_, i); }
  double raw(std::int64_t i) const { return at(raw_, i); }

  // Parameters in samples / adu.
  DetectorOptions o_;
  bool upside_down_ = false;  // DetectorOptions::gain was negative: samples are turned over
  std::int64_t win_, hold_, fpeak_timeout_, twave_, second_, relearn_, margin_, deriv_,
      bls_half_, bls_pair_;
  double bp_delay_, min_p2p_, frac_;
  std::int64_t refine_before_, refine_after_, locate_half_, centroid_half_, slope_half_;

  // Filters and the integration.
  Biquad hp_, lp_;
  std::int64_t n_ = 0;
  std::optional<std::int32_t> last_valid_;  // DetectorOptions::invalid_sample: the value held
  std::int64_t last_invalid_ = -1;          // and the index of the latest sample without a value
  // DetectorOptions::flat_run_ms in samples (0: off), the length of the run of equal samples
  // that ends at the latest one, and the latest runs at least that long ([first, last] sample;
  // a few, since a beat is accepted a while after it, and a run after it must not hide one in
  // the gap before it).
  std::int64_t flat_run_ = 0, same_run_ = 0;
  std::array<std::pair<std::int64_t, std::int64_t>, 4> flat_runs_{};
  std::size_t flat_runs_n_ = 0;
  double last_bp_ = 0, sum_ = 0, last_f_ = 0;
  // History rings of at least 4 s (power of two; allocated once): the longest look-back is
  // the integration window plus the 95 ms peak timeout plus the hold, and from the candidate's
  // QRS note_hum()'s 250 ms, well under 2 s.
  std::int64_t mask_;
  std::vector<double> bp_, d_, raw_;

  // The original signal through notches at 50 and 60 Hz (those below fs / 2), for locate()
  // while the signal carries mains hum (hum_present_, note_hum()). Hum moved the centroid of
  // the QRS with its phase: 0.3 mV of 50 Hz added to MIT-BIH took the RR error of normal beats
  // from 1.6 to 3.3 samples rms, 1 mV to 7.6. Q = 10 (5 Hz wide at 50 Hz) also takes out hum a
  // percent off its nominal frequency; a narrower notch let 49.5 Hz through. On a clean signal
  // the notches cost precision (their ringing spreads the QRS: records at the floor of 0.4
  // samples rms went to 0.6), hence the switch (docs/rpeak.md).
  std::vector<Biquad> notches_;
  std::vector<double> notched_;
  std::array<double, 8> hum_levels_{};  // note_hum()'s last levels, mV
  std::size_t hum_n_ = 0;
  bool hum_present_ = false;

  // Local-maximum finder of the integrated slope (Hamilton's Peak()).
  double fmax_ = 0;
  std::int64_t fmax_at_ = 0, since_max_ = 0;

  // The 200 ms hold.
  bool holding_ = false;
  Peak held_;
  std::int64_t hold_left_ = 0;

  // Adaptive state.
  bool learned_ = false;
  std::vector<Peak> learning_;  // candidates of the first seconds, replayed once learned
  std::array<double, 8> qrs_{}, noise_{}, rr_{};
  std::array<std::int64_t, 8> noise_at_{};  // R wave of each noise_ entry (-1: none)
  double qrs_med_ = 0, noise_med_ = 0, rr_med_ = 0;
  std::array<double, 8> second_max_{};  // background per-second maxima (relearning)
  // The band-passed peak-to-peak of the candidates behind second_max_ and of the last 8 QRS,
  // whose median scales the floor (floor()); second_p2p_ goes with second_peak_.
  std::array<double, 8> second_max_p2p_{}, qrs_p2p_{};
  double qrs_p2p_med_ = 0, second_p2p_ = 0;
  // The band-passed peak-to-peak of the last 32 local maxima of the integrated slope (all of
  // them, below the floor too) and its median: the ripple of the lead's baseline (floor()).
  std::array<double, 32> ripple_{};
  std::size_t ripple_n_ = 0;
  double ripple_med_ = 0;
  std::int64_t seconds_ = 0, next_second_ = 0;
  double second_peak_ = 0;
  bool have_qrs_ = false;
  std::int64_t last_qrs_ = 0;
  double last_slope_ = 0;
  bool have_sb_ = false;
  Peak sb_;
  double polarity_ = 0;  // running mean of the R-vs-S balance of recent beats, in [-1, 1]
  std::int64_t last_out_ = -1;
  bool finished_ = false;
  // last_qrs_ when a candidate above the threshold was last rejected as a T wave: that gap
  // may hide an early beat (gap_before).
  std::int64_t twave_rejected_after_ = -1;
  // Every local maximum of the integrated slope, newest at events_[(events_n_ - 1) % size]:
  // the evidence that a gap between beats is empty. Up to ~30 maxima a second pass the 15 Hz
  // low-pass, so 128 cover the 2 s gaps the NN rule keeps.
  struct Event {
    std::int64_t when;    // the band-passed QRS point (its steepest sample, less the delay)
    double height;
    std::int64_t peak;    // where the integrated slope peaked: events are stored in its order
  };
  std::array<Event, 128> events_{};
  std::size_t events_n_ = 0;
  // The P-wave template (DetectorOptions::pwave_fraction): the running mean of the original
  // signal over 2 p_half_ + 1 samples centred p_lead_ before each accepted beat, the line
  // between the window ends removed (the first 8 beats averaged, then an exponential mean
  // over about 8 beats). The search looks at every p_step_-th sample and centre first (about
  // 120 per second: a P wave has nothing above 10-15 Hz), then at every sample around the best
  // centre when that came within 0.1 of the threshold. At the full rate throughout, the chain
  // was 15 % slower (on MIT-BIH the test runs for every P and T wave above 5 % in a gap).
  std::int64_t p_half_, p_lead_, p_search_, p_step_;
  std::int64_t own_p_;  // DetectorOptions::own_pwave_ms in samples
  std::vector<double> p_mean_;
  bool p_ready_ = false;  // p_mean_ is not flat
  int p_beats_ = 0;
};

namespace {
// The options for the lead as it is upright: a negative gain (a lead recorded upside down) is
// its size, and the samples are turned over as they come (Impl::step).
DetectorOptions upright(DetectorOptions o) {
  o.gain = std::abs(o.gain);
  return o;
}
}  // namespace

RPeakDetector::Impl::Impl(const DetectorOptions& o)
    : o_(upright(o)),
      upside_down_(o.gain < 0),
      win_(samples(o.integration_ms, o.fs)),
      hold_(samples(o.hold_ms, o.fs)),
      fpeak_timeout_(samples(95, o.fs)),
      twave_(samples(o.twave_ms, o.fs)),
      second_(samples(1000, o.fs)),
      relearn_(std::clamp<std::int64_t>(std::llround(o.relearn_s), 1, 8)),
      margin_(samples(40, o.fs)),
      deriv_(samples(10, o.fs)),
      bls_half_(samples(110, o.fs)),
      bls_pair_(samples(150, o.fs)),
      bp_delay_(0),
      min_p2p_(o.min_qrs_mv * std::abs(o.gain)),
      frac_(o.threshold_fraction),
      refine_before_(samples(50, o.fs)),
      refine_after_(samples(30, o.fs)),
      locate_half_(samples(60, o.fs)),
      centroid_half_(samples(42, o.fs)),
      slope_half_(samples(100, o.fs)),
      hp_(butterworth(o.highpass_hz, o.fs, true)),
      lp_(butterworth(o.lowpass_hz, o.fs, false)),
      p_half_(samples(80, o.fs)),
      p_lead_(samples(170, o.fs)),
      p_search_(samples(80, o.fs)),
      p_step_(std::max<std::int64_t>(1, std::llround(o.fs / 120))),
      own_p_(std::llround(o.own_pwave_ms * o.fs / 1000)) {
  flat_run_ = o.flat_run_ms > 0 ? std::max<std::int64_t>(2, std::llround(o.flat_run_ms * o.fs / 1000)) : 0;
  for (double mains_hz : {50.0, 60.0})
    if (mains_hz < o.fs / 2) notches_.push_back(notch(mains_hz, o.fs, 10));
  bp_delay_ = group_delay(hp_, lp_, std::sqrt(o.highpass_hz * o.lowpass_hz), o.fs);
  std::int64_t ring = 1024;
  while (ring < 4 * second_) ring *= 2;
  mask_ = ring - 1;
  bp_.assign(static_cast<std::size_t>(ring), 0.0);
  d_.assign(static_cast<std::size_t>(ring), 0.0);
  raw_.assign(static_cast<std::size_t>(ring), 0.0);
  notched_.assign(static_cast<std::size_t>(ring), 0.0);
  next_second_ = second_;
  learning_.reserve(128);
  p_mean_.assign(static_cast<std::size_t>(2 * p_half_ + 1), 0.0);
  noise_at_.fill(-1);
}

void RPeakDetector::Impl::push(const std::int32_t* s, std::size_t n,
                               std::vector<std::int64_t>& out) {
  if (finished_) return;
  for (std::size_t i = 0; i < n; ++i) step(s[i], out);
}

void RPeakDetector::Impl::step(std::int32_t x, std::vector<std::int64_t>& out) {
  const std::int64_t n = n_;
  const bool no_value = o_.invalid_sample && x == *o_.invalid_sample;
  if (upside_down_ && !no_value) x = x == std::numeric_limits<std::int32_t>::min() ? std::numeric_limits<std::int32_t>::max() : -x;
  if (o_.invalid_sample) {
    if (no_value) {
      last_invalid_ = n;
      x = last_valid_.value_or(0);
    } else {
      // The signal comes back at another level than the one held: the filters start again in
      // their steady state for it, as at the first sample, or the step rang through the band
      // as a beat just after the run.
      if (n > 0 && last_invalid_ == n - 1) {
        hp_.settle(x, 0);
        lp_.settle(0, 0);
        for (Biquad& n50_60 : notches_) n50_60.settle(x, x);
      }
      last_valid_ = x;
    }
  }
  if (n == 0) {
    // Start the high-pass in its steady state for a constant input equal to the first sample
    // (output 0), so the ADC offset does not ring through the filters as a fake first beat.
    hp_.settle(x, 0);
    for (Biquad& n50_60 : notches_) n50_60.settle(x, x);
  }
  const auto slot = static_cast<std::size_t>(n & mask_);
  if (flat_run_ > 0) {
    same_run_ = n > 0 && raw_[static_cast<std::size_t>((n - 1) & mask_)] == x ? same_run_ + 1 : 1;
    if (same_run_ == flat_run_) flat_runs_[flat_runs_n_++ % flat_runs_.size()] = {n - flat_run_ + 1, n};
    else if (same_run_ > flat_run_) flat_runs_[(flat_runs_n_ - 1) % flat_runs_.size()].second = n;
  }
  raw_[slot] = x;
  double notched = x;
  for (Biquad& n50_60 : notches_) notched = n50_60.step(notched);
  notched_[slot] = notched;
  const double b = lp_.step(hp_.step(x));
  bp_[slot] = b;
  const double d = std::fabs(b - last_bp_);
  last_bp_ = b;
  d_[slot] = d;
  sum_ += d - (n >= win_ ? slope(n - win_) : 0.0);
  const double f = sum_;

  // Local maxima of f: released when f falls to half of it or 95 ms pass.
  if (since_max_ > 0) ++since_max_;
  if (f > last_f_ && f > fmax_) {
    fmax_ = f;
    fmax_at_ = n;
    since_max_ = 1;
  } else if (fmax_ > 0 && (f < fmax_ / 2 || since_max_ > fpeak_timeout_)) {
    on_fpeak(fmax_, fmax_at_);
    fmax_ = 0;
    since_max_ = 0;
  }
  last_f_ = f;

  // The hold: a candidate is decided when no larger one came for hold_ samples.
  if (holding_ && --hold_left_ <= 0) release_held(out);
  if (learned_ && gap_classified()) searchback(n - delay(), out);
  if (tick(n) && !learned_) {
    learned_ = true;
    seed_noise();
    // Classify what was held back while learning (a handful of peaks), in order.
    for (const Peak& p : learning_) classify(p, out);
    learning_.clear();
  }
  ++n_;
}

// The least band-passed peak-to-peak amplitude of a candidate (DetectorOptions::min_qrs_mv,
// min_qrs_fraction, min_qrs_baseline): the ripple of the lead's own baseline (the median
// peak-to-peak of its last 32 local maxima, most of which are neither QRS nor T wave) decides
// what is too small to be a beat, so the floor scales with the lead. It never exceeds a
// fraction of the lead's QRS (where most maxima are waves: fast rates, noise), and never
// falls below an absolute floor under which only amplifier noise lies. While no QRS is known
// (the learning seconds, or after relearning found nothing) the floor is the absolute one.
// The floor used to be 0.15 mV: MIT-BIH 101's V1, whose QRS is 0.1-0.3 mV band-passed, then
// gave 3 beats of 1523, and the whole database at a fifth of its gain 87 % of its beats.
// A floor in proportion to the QRS alone did not do: MIT-BIH 108's quiet baseline holds
// bumps of 0.2-0.4 of its QRS (in integrated slope), which then filled the noise median and
// let its tall P waves through as beats (docs/rpeak.md, step 3).
double RPeakDetector::Impl::floor() const {
  return std::max(min_p2p_, std::min(o_.min_qrs_fraction * qrs_p2p_med_,
                                     o_.min_qrs_baseline * ripple_med_));
}

// Folds a local maximum's band-passed peak-to-peak into the ripple median (upper median of
// the last 32, or of those there are). A few a second: the partial sort is nothing per sample.
void RPeakDetector::Impl::note_ripple(double p2p) {
  ripple_[ripple_n_++ % ripple_.size()] = p2p;
  const std::size_t have = std::min(ripple_n_, ripple_.size());
  std::array<double, 32> sorted = ripple_;
  const auto mid = sorted.begin() + static_cast<std::ptrdiff_t>(have / 2);
  std::nth_element(sorted.begin(), mid, sorted.begin() + static_cast<std::ptrdiff_t>(have));
  ripple_med_ = *mid;
}

void RPeakDetector::Impl::on_fpeak(double height, std::int64_t at) {
  // The QRS that made this peak of the integrated slope lies in the window before it.
  const std::int64_t lo = std::max<std::int64_t>(0, at - win_ - margin_);
  double hi_v = -1e300, lo_v = 1e300, best = -1, max_slope = 0;
  std::int64_t best_at = at;
  for (std::int64_t i = lo; i <= at; ++i) {
    const double v = bp(i);
    hi_v = std::max(hi_v, v);
    lo_v = std::min(lo_v, v);
    if (std::fabs(v) > best) best = std::fabs(v), best_at = i;
    max_slope = std::max(max_slope, slope(i));
  }
  // Below the floor it is never a beat, but it still counts against an empty gap: a small
  // missed QRS often lies there.
  events_[events_n_++ % events_.size()] = {
      std::max<std::int64_t>(0, best_at - std::llround(bp_delay_)), height, at};
  note_ripple(hi_v - lo_v);
  if (hi_v - lo_v < floor()) return;  // below the floor: never a beat
  Peak p;
  p.height = height;
  p.p2p = hi_v - lo_v;
  p.max_slope = max_slope;
  p.qrs = std::max<std::int64_t>(0, best_at - std::llround(bp_delay_));
  p.at = fiducial(p.qrs, p.balance);
  if (!holding_ || height > held_.height) {
    held_ = p;
    holding_ = true;
    hold_left_ = hold_;
  }
}

// The R wave on the original signal: the dominant extremum from 50 ms before to 30 ms after the
// band-passed QRS, measured from the local baseline (Baseline: wander does not move it). The window
// looks further back than forward because the band-passed point is, if anything, late: wide
// complexes carry more energy at low frequencies, which the band-pass delays more than its
// centre (on paced or V2 leads a symmetric ±50 ms pushed some points past the 150 ms match).
// The dominant polarity of the lead (a running mean over beats) decides between an R and an S
// wave of similar size, so consecutive beats of one morphology get the same fiducial point and
// RR intervals do not jitter by an R–S distance; a wave of the other polarity wins only when
// twice as large.
// `balance` gets (R − S) / (R + S) of this complex; accept() folds it into the polarity.
auto RPeakDetector::Impl::deflections(std::int64_t qrs, std::int64_t before, std::int64_t after,
                                      const std::vector<double>& signal) const -> std::optional<Deflections> {
  const std::int64_t lo = std::max<std::int64_t>(0, qrs - before);
  const std::int64_t hi = std::min<std::int64_t>(n_ - 1, qrs + after);
  if (hi - lo < 2) return std::nullopt;
  const Baseline base(signal, lo, hi, *this);
  Deflections d{0, 0, qrs, qrs};
  for (std::int64_t i = lo; i <= hi; ++i) {
    const double v = at(signal, i) - base(i);
    if (v > d.up) d.up = v, d.up_at = i;
    if (-v > d.down) d.down = -v, d.down_at = i;
  }
  if (d.up + d.down <= 0) return std::nullopt;
  return d;
}

std::int64_t RPeakDetector::Impl::fiducial(std::int64_t qrs, double& balance) const {
  auto d = deflections(qrs, refine_before_, refine_after_, raw_);
  if (!d) return qrs;
  balance = (d->up - d->down) / (d->up + d->down);
  return dominant_positive(d->up, d->down) ? d->up_at : d->down_at;
}

// Between a positive deflection `up` and a negative one `down` (both > 0), the lead's dominant
// polarity wins unless the other deflection is 1.5 times as large.
bool RPeakDetector::Impl::dominant_positive(double up, double down) const {
  return polarity_ >= 0 ? !(down > 1.5 * up) : (up > 1.5 * down);
}

// The point reported for a beat, computed when the hold ends (at least 200 ms of signal after
// the QRS are then in the rings). RR intervals, hence HRV, are differences of these points, so
// what matters is that every beat of one morphology gets the same point to the sample; the
// detection point fiducial() is not good enough for that (its window is cut 30 ms after the
// band-passed point, so it sometimes takes a Q wave or the downslope instead of the R peak, and
// the arg max of a flat-topped R wave jitters by a sample with noise). Two steps, on the original
// signal (with mains hum notched out while there is hum, notched_):
//  1. the dominant extremum within ±60 ms of the band-passed point,
//     measured from the local baseline (Baseline), chosen by the lead's polarity as fiducial()
//     does: the main deflection of the QRS;
//  2. the centroid of the squared deviation from the local baseline (Baseline of its window)
//     over ±42 ms around that extremum, recentred twice: the centre of the QRS's main energy.
//     The centroid averages over the whole deflection, so it does not jitter with noise on the
//     peak or with a change of polarity between near-equal R and S waves, and it stays on the
//     QRS (the window is about one QRS width).
// On MIT-BIH this lies within a sample of the reference annotation for most records (which are
// near the peak of the main deflection), and the scatter of (beat − annotation) from one
// normal beat to the next falls from 2.0 to 1.6 samples rms over all 45 records — 0.4–0.5 in
// most, the floor set by the annotations' own rounding to whole samples (docs/rpeak.md).
std::int64_t RPeakDetector::Impl::locate(std::int64_t qrs) const {
  const std::vector<double>& signal = hum_present_ ? notched_ : raw_;
  auto d = deflections(qrs, locate_half_, locate_half_, signal);
  if (!d) return qrs;
  const std::int64_t peak = dominant_positive(d->up, d->down) ? d->up_at : d->down_at;
  double centre = static_cast<double>(peak);
  for (int pass = 0; pass < 3; ++pass) {
    const std::int64_t mid = std::llround(centre);
    const std::int64_t a = std::max<std::int64_t>(0, mid - centroid_half_);
    const std::int64_t b = std::min<std::int64_t>(n_ - 1, mid + centroid_half_);
    const Baseline level(signal, a, b, *this);
    double weight = 0, moment = 0;
    for (std::int64_t i = a; i <= b; ++i) {
      const double e = (at(signal, i) - level(i)) * (at(signal, i) - level(i));
      weight += e;
      moment += e * static_cast<double>(i);
    }
    if (!(weight > 0)) break;
    centre = moment / weight;
  }
  // Recentring moves at most one window per pass; keep the point within one window of the
  // peak, so the decision delay stays bounded.
  return std::clamp<std::int64_t>(std::llround(centre), peak - centroid_half_,
                                  peak + centroid_half_);
}

// What the notches take out of the signal from 250 to 100 ms before a candidate (before a beat,
// the PR segment and the P wave, where an ECG has nothing near 50 or 60 Hz; at a fast rate, or
// before a T wave or noise, also the tail of the complex before, which a median discounts),
// rms in mV, as a median over the last 8 candidates (those there are from the third on, so
// that the first seconds of a stream with hum are not located on the original); locate()
// works on the notched signal from 0.02 mV on, and on the original again below 0.015. On
// clean MIT-BIH records that level is 0.009 mV at the median candidate; 0.03 mV of hum
// (amplitude) gives 0.023.
void RPeakDetector::Impl::note_hum(std::int64_t qrs) {
  constexpr double kHumOnMv = 0.02, kHumOffMv = 0.015;
  const std::int64_t a = std::max<std::int64_t>(0, qrs - samples(250, o_.fs));
  const std::int64_t b = std::max<std::int64_t>(0, qrs - samples(100, o_.fs));
  if (b - a < 4 || notches_.empty()) return;
  double e = 0;
  for (std::int64_t i = a; i < b; ++i) {
    const double h = raw(i) - at(notched_, i);
    e += h * h;
  }
  hum_levels_[hum_n_++ % hum_levels_.size()] = std::sqrt(e / static_cast<double>(b - a)) / o_.gain;
  if (hum_n_ < 3) return;
  const std::size_t have = std::min(hum_n_, hum_levels_.size());
  std::array<double, 8> sorted = hum_levels_;
  std::sort(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(have));
  const double level = have % 2 ? sorted[have / 2] : (sorted[have / 2 - 1] + sorted[have / 2]) / 2;
  hum_present_ = hum_present_ ? level > kHumOffMv : level > kHumOnMv;
}

// The hold is over: the held candidate is decided now.
void RPeakDetector::Impl::release_held(std::vector<std::int64_t>& out) {
  holding_ = false;
  held_.decided = n_;
  held_.baseline_shift = baseline_shift(held_.at);
  note_hum(held_.qrs);
  held_.beat = locate(held_.qrs);
  on_candidate(held_, out);
}

void RPeakDetector::Impl::on_candidate(const Peak& p, std::vector<std::int64_t>& out) {
  if (p.height > second_peak_) second_peak_ = p.height, second_p2p_ = p.p2p;
  if (!learned_) {
    learning_.push_back(p);
    return;
  }
  classify(p, out);
}

// Baseline-shift test (Hamilton's BLSCheck): a QRS has both a rising and a falling slope of
// comparable size, less than 150 ms apart; a step of the baseline has only one.
bool RPeakDetector::Impl::baseline_shift(std::int64_t at) const {
  double up = 0, down = 0;
  std::int64_t up_at = at, down_at = at;
  const std::int64_t lo = std::max<std::int64_t>(deriv_, at - bls_half_);
  for (std::int64_t i = lo; i <= at + bls_half_ && i < n_; ++i) {
    const double v = raw(i) - raw(i - deriv_);
    if (v > up) up = v, up_at = i;
    if (v < down) down = v, down_at = i;
  }
  down = -down;
  return !(up > down / 8 && down > up / 8 && std::llabs(up_at - down_at) < bls_pair_);
}

void RPeakDetector::Impl::classify(const Peak& p, std::vector<std::int64_t>& out) {
  searchback(p.at, out);
  if (p.baseline_shift) return;
  // The candidates of the learning seconds passed only the noise floor (no QRS was known
  // then); from the first classification on, the floor of the learned QRS applies to them.
  if (p.p2p < floor()) return;
  const bool twave = have_qrs_ && p.at - last_qrs_ < twave_ &&
                     p.max_slope < o_.twave_slope_ratio * last_slope_;
  if (p.height > threshold() && !twave) {
    accept(p, out);
    return;
  }
  if (twave && p.height > threshold()) twave_rejected_after_ = last_qrs_;
  shift_in(noise_, p.height);
  shift_in(noise_at_, p.at);
  noise_med_ = median8(noise_);
  if (!have_qrs_ || p.at - last_qrs_ >= twave_) {
    if (!have_sb_ || p.height > sb_.height) sb_ = p, have_sb_ = true;
  }
}

// Search-back (Hamilton): when no QRS followed the last one within searchback_rr × the median
// RR, the largest noise peak in the gap is taken for a missed beat if it reached
// searchback_fraction × the threshold. Called per sample (once every candidate in the gap has
// been classified: nothing held, no local maximum pending) and before classifying a candidate
// that lies beyond the gap.
// Whether every candidate in the search-back gap after the last QRS has been classified by
// now: none is held or still rising in the integrator with its R wave inside the gap.
bool RPeakDetector::Impl::gap_classified() const {
  const double gap_end = static_cast<double>(last_qrs_) + o_.searchback_rr * rr_med_;
  if (holding_ && static_cast<double>(held_.at) <= gap_end) return false;
  return fmax_ == 0 || static_cast<double>(fmax_at_ - win_ - margin_) > gap_end;
}

void RPeakDetector::Impl::searchback(std::int64_t now, std::vector<std::int64_t>& out) {
  if (!have_qrs_ || !have_sb_) return;
  if (static_cast<double>(now - last_qrs_) <= o_.searchback_rr * rr_med_) return;
  if (sb_.height > o_.searchback_fraction * threshold()) {
    const Peak p = sb_;
    unfile_noise(p.at);
    accept(p, out);
  }
}

// A beat found by search-back was filed as noise when it was classified: take it out of the
// noise buffer (the oldest entry fills the gap). Otherwise, after a sudden drop of amplitude,
// the noise median climbs to the height of the beats themselves and every later beat is found
// only by search-back.
void RPeakDetector::Impl::unfile_noise(std::int64_t at) {
  const auto it = std::find(noise_at_.begin(), noise_at_.end(), at);
  if (it == noise_at_.end()) return;
  const auto i = static_cast<std::size_t>(it - noise_at_.begin());
  std::copy(noise_.begin() + static_cast<std::ptrdiff_t>(i) + 1, noise_.end(),
            noise_.begin() + static_cast<std::ptrdiff_t>(i));
  std::copy(noise_at_.begin() + static_cast<std::ptrdiff_t>(i) + 1, noise_at_.end(),
            noise_at_.begin() + static_cast<std::ptrdiff_t>(i));
  noise_[7] = noise_[6];
  noise_at_[7] = -1;
  noise_med_ = median8(noise_);
}

// Whether the gap before a beat accepted at `at` holds nothing QRS-like: every local maximum of
// the integrated slope from the end of the previous beat's T wave (twave_, or later at slow
// rates: DetectorOptions::twave_qtc, with rr_[0] the interval before that beat) to hold_ before
// this one
// (this complex and its P wave) stayed below empty_gap_fraction of the QRS median, or is a P
// wave (pwave_at; then the gap held a blocked P wave), or is this beat's own P wave: below
// pwave_fraction and within own_p_ before it (DetectorOptions::own_pwave_ms; a long PR interval
// puts it past hold_). Only a gap entirely covered by the event ring can be confirmed.
auto RPeakDetector::Impl::gap_before(std::int64_t at) const -> Gap {
  Gap gap;
  if (!have_qrs_ || !(o_.empty_gap_fraction > 0) || !(qrs_med_ > 0)) return gap;
  // Samples without a value (DetectorOptions::invalid_sample) in the gap: held flat, they would
  // confirm as empty a gap whose beat was simply not recorded.
  if (last_invalid_ > last_qrs_) return gap;
  // Nor can a gap with a run of one value repeated (DetectorOptions::flat_run_ms): no signal.
  for (std::size_t k = 0; k < std::min(flat_runs_n_, flat_runs_.size()); ++k)
    if (flat_runs_[k].second > last_qrs_ && flat_runs_[k].first < at) return gap;
  // A candidate as tall as a beat, rejected as a T wave only for its slope: an early beat
  // (an APC or PVC on the T wave) whose compensatory pause this is. Its QRS point lies before
  // the gap's start, so no maximum below would show it.
  if (twave_rejected_after_ == last_qrs_) return gap;
  const std::int64_t qt = std::llround(o_.twave_qtc * std::sqrt(rr_[0] / o_.fs) * o_.fs);
  // The T wave ends before the next beat: at fast rates twave_ms reaches past where a missed
  // beat would lie (at 150 bpm a beat comes 400 ms after the one before; a small missed one
  // had its QRS point 305 ms after it, inside twave_ms), so the gap starts by
  // kTwaveRrFraction of the median interval at the latest (of the interval before, it started
  // inside the T wave of an early beat, which then passed for a P wave). There, a maximum is in
  // the gap when the integrated slope peaked in it: a small QRS just after the T wave had its
  // steepest band-passed sample, its QRS point, on that T wave.
  const std::int64_t t_end_by_qt = std::max(twave_, qt);
  const std::int64_t t_end =
      rr_med_ > 0 ? std::min<std::int64_t>(t_end_by_qt, std::llround(kTwaveRrFraction * rr_med_)) : t_end_by_qt;
  const bool cut = t_end < t_end_by_qt;
  const std::int64_t from = last_qrs_ + t_end, to = at - hold_;
  // This beat's own P wave lies after where a beat at the usual interval would (else a small
  // missed beat at a fast rate, 300 ms or less before this one, was taken for it).
  const std::int64_t own_p = std::max<std::int64_t>(at - own_p_, last_qrs_ + std::llround(kMissedBeatLateRr * rr_med_));
  // At fast rates the P-wave template (250-90 ms before each beat) holds the T wave of the
  // beat before, and a small missed QRS correlated with it at 0.9 or more.
  const bool p_cue = rr_med_ >= kPwaveCueMinRrS * o_.fs;
  const double limit = o_.empty_gap_fraction * qrs_med_;
  const double p_limit = o_.pwave_fraction * qrs_med_;
  const std::size_t kept = std::min(events_n_, events_.size());
  bool covered = events_n_ <= events_.size();  // the ring reaches back to the start
  for (std::size_t k = 1; k <= kept; ++k) {
    const auto& [when, height, peak] = events_[(events_n_ - k) % events_.size()];
    // Events are stored in the order of their integrator maxima, which may put a QRS point
    // up to one window (plus margin) before that of an older event: stop only past that.
    if (when + win_ + margin_ <= from && peak <= from) {
      covered = true;
      break;
    }
    if ((cut ? peak : when) > from && when < to && height >= limit) {
      if (p_cue && pwave_at(when, height)) {
        gap.p_wave = true;  // shaped like the template (this beat's own P wave too, as before)
      } else if (when < own_p || height >= p_limit) {
        return Gap{};  // nor this beat's own P wave, which may have any shape
      }
    }
  }
  if (!covered) return Gap{};
  gap.empty = true;
  return gap;
}

// Whether a gap maximum of `height` at `when` is a P wave: small, and shaped like the
// record's own P wave (DetectorOptions::pwave_fraction). A blocked P wave in second-degree AV
// block reaches 7-10 % of the QRS height in the integrated slope, as much as a small missed
// QRS; only the shape tells them apart.
bool RPeakDetector::Impl::pwave_at(std::int64_t when, double height) const {
  if (!(o_.pwave_fraction > 0) || p_beats_ < 8 || !(height < o_.pwave_fraction * qrs_med_))
    return false;
  double best = -1;
  std::int64_t best_at = when;
  for (std::int64_t c = when - p_search_; c <= when + p_search_; c += p_step_) {
    const double r = pwave_correlation(c, p_step_);
    if (r >= o_.pwave_correlation) return true;
    if (r > best) best = r, best_at = c;
  }
  if (p_step_ == 1 || best < o_.pwave_correlation - 0.1) return false;
  for (std::int64_t c = best_at - p_step_ + 1; c < best_at + p_step_; ++c)
    if (pwave_correlation(c, 1) >= o_.pwave_correlation) return true;
  return false;
}

// Pearson correlation of the original signal over [centre - p_half_, centre + p_half_] (every
// stride-th sample), the line between its ends removed, with the P-wave template; -1 when the
// window is not (or no longer) in the ring or either is flat.
double RPeakDetector::Impl::pwave_correlation(std::int64_t centre, std::int64_t stride) const {
  const std::int64_t lo = centre - p_half_, hi = centre + p_half_;
  if (!p_ready_ || lo < 0 || lo < n_ - mask_ || hi > n_ - 1) return -1;
  const double a = raw(lo), step = (raw(hi) - a) / static_cast<double>(hi - lo);
  double sv = 0, svv = 0, st = 0, stt = 0, svt = 0, m = 0;
  for (std::int64_t i = lo; i <= hi; i += stride) {
    const double v = raw(i) - a - step * static_cast<double>(i - lo);
    const double t = p_mean_[static_cast<std::size_t>(i - lo)];
    sv += v, svv += v * v, st += t, stt += t * t, svt += v * t, m += 1;
  }
  const double var_v = svv - sv * sv / m, var_t = stt - st * st / m;
  return var_v > 0 && var_t > 0 ? (svt - sv * st / m) / std::sqrt(var_v * var_t) : -1;
}

// Folds the signal before an accepted beat into the P-wave template. Beats whose window has
// left the ring (those of the learning seconds) are skipped.
void RPeakDetector::Impl::learn_pwave(std::int64_t beat) {
  const std::int64_t lo = beat - p_lead_ - p_half_, hi = beat - p_lead_ + p_half_;
  if (!(o_.pwave_fraction > 0) || lo < 0 || lo < n_ - mask_ || hi > n_ - 1) return;
  const double weight = p_beats_ < 8 ? 1.0 / (p_beats_ + 1) : 0.125;
  const double a = raw(lo), step = (raw(hi) - a) / static_cast<double>(hi - lo);
  bool flat = true;
  for (std::int64_t i = lo; i <= hi; ++i) {
    double& m = p_mean_[static_cast<std::size_t>(i - lo)];
    m += weight * (raw(i) - a - step * static_cast<double>(i - lo) - m);
    flat = flat && m == p_mean_[0];
  }
  p_ready_ = !flat;
  ++p_beats_;
}

void RPeakDetector::Impl::accept(const Peak& p, std::vector<std::int64_t>& out) {
  const Gap gap = gap_before(p.at);
  learn_pwave(p.beat);
  shift_in(qrs_, p.height);
  qrs_med_ = median8(qrs_);
  shift_in(qrs_p2p_, p.p2p);
  qrs_p2p_med_ = median8(qrs_p2p_);
  if (have_qrs_) {
    shift_in(rr_, static_cast<double>(p.at - last_qrs_));
    rr_med_ = median8(rr_);
  }
  have_qrs_ = true;
  last_qrs_ = p.at;
  last_slope_ = p.max_slope;
  polarity_ += 0.1 * (p.balance - polarity_);
  have_sb_ = false;
  seconds_ = 0;
  second_peak_ = 0;
  second_p2p_ = 0;
  if (p.beat > last_out_) {
    out.push_back(p.beat);
    if (gap.empty && empty_gap_out_) empty_gap_out_->push_back(p.beat);
    if (gap.empty && gap.p_wave && p_wave_gap_out_) p_wave_gap_out_->push_back(p.beat);
    last_out_ = p.beat;
  }
}

// Per-second maxima of the candidates: the first `relearn_s` seconds teach the thresholds;
// later, as many seconds without a QRS relearn them (a change of lead, gain or rhythm).
// Returns true when the thresholds were (re)learned at sample `now`.
bool RPeakDetector::Impl::tick(std::int64_t now) {
  if (now < next_second_) return false;
  next_second_ = now + second_;
  second_max_[static_cast<std::size_t>(seconds_)] = second_peak_;
  second_max_p2p_[static_cast<std::size_t>(seconds_)] = second_p2p_;
  second_peak_ = 0;
  second_p2p_ = 0;
  if (++seconds_ < relearn_) return false;
  seconds_ = 0;
  learn(relearn_);
  return true;
}

// The thresholds from the per-second maxima of the first `seconds` entries of second_max_.
void RPeakDetector::Impl::learn(std::int64_t seconds) {
  for (std::size_t i = 0; i < 8; ++i) {
    qrs_[i] = second_max_[i % static_cast<std::size_t>(seconds)];
    qrs_p2p_[i] = second_max_p2p_[i % static_cast<std::size_t>(seconds)];
  }
  qrs_med_ = median8(qrs_);
  qrs_p2p_med_ = median8(qrs_p2p_);
  noise_.fill(0);
  noise_at_.fill(-1);
  noise_med_ = 0;
  rr_.fill(static_cast<double>(second_));
  rr_med_ = static_cast<double>(second_);
  have_sb_ = false;
}

// The noise level at the end of learning: the median height of the learning candidates below
// half the QRS estimate (Hamilton starts from 0). Starting from 0 in a noisy lead puts the
// first threshold at 0.31 × the QRS height, under the noise peaks; accepted noise then pulls
// the QRS median down and the detector runs away counting noise (seen with ECGSYN at 128 Hz,
// 0.2 mV noise, 40 bpm: 400 false beats in 300 s).
void RPeakDetector::Impl::seed_noise() {
  std::array<double, 8> quiet{};
  std::size_t count = 0;
  for (auto it = learning_.rbegin(); it != learning_.rend() && count < quiet.size(); ++it)
    if (it->height < qrs_med_ / 2 && it->p2p >= floor()) quiet[count++] = it->height;
  if (count == 0) return;
  std::sort(quiet.begin(), quiet.begin() + static_cast<std::ptrdiff_t>(count));
  const double level = (quiet[(count - 1) / 2] + quiet[count / 2]) / 2;
  noise_.fill(level);
  noise_med_ = level;
}

void RPeakDetector::Impl::finish(std::vector<std::int64_t>& out) {
  if (finished_) return;
  if (fmax_ > 0) on_fpeak(fmax_, fmax_at_);
  if (holding_) release_held(out);
  if (!learned_ && !learning_.empty()) {
    // A stream shorter than the learning period (a record of a few seconds): the thresholds
    // come from the seconds it has, and its candidates are classified, not dropped.
    second_max_[static_cast<std::size_t>(seconds_)] = second_peak_;
    second_max_p2p_[static_cast<std::size_t>(seconds_)] = second_p2p_;
    learn(seconds_ + 1);
    learned_ = true;
    seed_noise();
    for (const Peak& p : learning_) classify(p, out);
    learning_.clear();
  }
  finished_ = true;
}

RPeakDetector::RPeakDetector(const DetectorOptions& options) {
  if (auto ok = validate(options); !ok) throw std::invalid_argument(ok.error().message);
  impl_ = std::make_unique<Impl>(options);
}
RPeakDetector::RPeakDetector(RPeakDetector&&) noexcept = default;
RPeakDetector& RPeakDetector::operator=(RPeakDetector&&) noexcept = default;
RPeakDetector::~RPeakDetector() = default;

void RPeakDetector::push(const std::int32_t* samples, std::size_t n,
                         std::vector<std::int64_t>& peaks_out) {
  impl_->push(samples, n, peaks_out);
}
void RPeakDetector::finish(std::vector<std::int64_t>& peaks_out) { impl_->finish(peaks_out); }
void RPeakDetector::push(const std::int32_t* samples, std::size_t n,
                         std::vector<std::int64_t>& peaks_out,
                         std::vector<std::int64_t>& empty_gap_out) {
  impl_->empty_gap_out_ = &empty_gap_out;
  impl_->push(samples, n, peaks_out);
  impl_->empty_gap_out_ = nullptr;
}
void RPeakDetector::finish(std::vector<std::int64_t>& peaks_out,
                           std::vector<std::int64_t>& empty_gap_out) {
  impl_->empty_gap_out_ = &empty_gap_out;
  impl_->finish(peaks_out);
  impl_->empty_gap_out_ = nullptr;
}
void RPeakDetector::push(const std::int32_t* samples, std::size_t n,
                         std::vector<std::int64_t>& peaks_out,
                         std::vector<std::int64_t>& empty_gap_out,
                         std::vector<std::int64_t>& p_wave_gap_out) {
  impl_->p_wave_gap_out_ = &p_wave_gap_out;
  push(samples, n, peaks_out, empty_gap_out);
  impl_->p_wave_gap_out_ = nullptr;
}
void RPeakDetector::finish(std::vector<std::int64_t>& peaks_out,
                           std::vector<std::int64_t>& empty_gap_out,
                           std::vector<std::int64_t>& p_wave_gap_out) {
  impl_->p_wave_gap_out_ = &p_wave_gap_out;
  finish(peaks_out, empty_gap_out);
  impl_->p_wave_gap_out_ = nullptr;
}
std::int64_t RPeakDetector::decision_delay_samples() const noexcept { return impl_->delay(); }

std::vector<std::int64_t> detect_r_peaks(const std::vector<std::int32_t>& samples,
                                         const DetectorOptions& options) {
  RPeakDetector detector(options);
  std::vector<std::int64_t> peaks;
  detector.push(samples.data(), samples.size(), peaks);
  detector.finish(peaks);
  return peaks;
}

Detection detect_beats(const std::vector<std::int32_t>& samples, const DetectorOptions& options) {
  RPeakDetector detector(options);
  Detection d;
  detector.push(samples.data(), samples.size(), d.peaks, d.empty_gap_ends, d.p_wave_gap_ends);
  detector.finish(d.peaks, d.empty_gap_ends, d.p_wave_gap_ends);
  return d;
}

}  // namespace tahvel::aggregation
