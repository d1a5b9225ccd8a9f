// ECGSYN (McSharry et al. 2003) as a per-sample state machine, so that chunking cannot change
// the output. Tuned for agents producing real-time ECG (a few hundred samples per second) and
// for tests producing tens of minutes in well under a second.
//
// The pieces, each in its own small function:
//   Rng        — mt19937_64 → uniform (0,1) → normal by Box–Muller (our code: portable).
//   Tachogram  — RR deviations in blocks of 512 s, each the inverse DFT of the bimodal
//                spectrum with random phases, cross-faded (sine window, 50 % overlap:
//                sin² + cos² = 1 keeps the variance) so that block edges do not show.
//   Morphology — the five Gaussian events, normal or ectopic, scaled with the mean heart rate.
//   State      — RK4 integration of (x, y, z) at ≥ 500 Hz, beat bookkeeping at θ = 0 and
//                the morphology switch at θ = ±π (diastole, where no event has weight).
#include "tahvel/aggregation/ecgsyn.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <limits>
#include <numbers>
#include <random>
#include <sstream>
#include <string>

namespace tahvel::aggregation {
namespace {

constexpr double kTwoPi = 2 * std::numbers::pi;

// Tachogram: block length and hop (s), highest frequency kept (Hz: the DFT has bins k/512 Hz
// for k = 1 … 512) and the width (SD) of each spectral peak (ECGSYN's flostd = fhistd).
constexpr double kBlockS = 512;
constexpr double kHopS = kBlockS / 2;
constexpr int kBins = 512;
constexpr double kPeakSdHz = 0.01;

// Ectopic beats come at this fraction of the RR interval; the next interval is (2 − c)·RR,
// so that the two add up to two normal intervals (full compensatory pause).
constexpr double kEctopicCoupling = 0.6;

// ECGSYN scales the output to −0.4…1.2 mV: a peak-to-peak of 1.6 mV at the mean heart rate.
constexpr double kPeakToPeakMv = 1.6;

// ---------------------------------------------------------------------------------------
// Random numbers, identical on every standard library.

std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

class Rng {
 public:
  // Each use (tachogram, noise, ectopy, wander) draws from its own stream, so that the
  // number of draws in one cannot shift another.
  Rng(std::uint64_t seed, std::uint64_t stream) : engine_(splitmix64(seed ^ splitmix64(stream))) {}

  // Uniform in the open interval (0, 1): 53 random bits, centred in their cell.
  double uniform() { return (static_cast<double>(engine_() >> 11) + 0.5) * 0x1p-53; }

  // Standard normal by Box–Muller; the second value of each pair is kept for the next call.
  double normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    const double r = std::sqrt(-2 * std::log(uniform()));
    const double phi = kTwoPi * uniform();
    spare_ = r * std::sin(phi);
    has_spare_ = true;
    return r * std::cos(phi);
  }

 private:
  std::mt19937_64 engine_;
  double spare_ = 0;
  bool has_spare_ = false;
};

// ---------------------------------------------------------------------------------------
// The RR tachogram: rr(t) = mean + d(t). d is made in blocks of 512 s, each the inverse DFT
// of the bimodal spectrum with uniform random phases, d_b(u) = Σk Ak cos(2πku/512 + φk).
// The inverse DFT is a trigonometric polynomial, so it is evaluated exactly at the instant of
// each beat rather than on a grid then interpolated (linear interpolation of a 2 Hz grid
// would lose 8 % of the HF variance). Blocks overlap by half and are cross-faded with
// w(u) = sin(πu/512): w² of one plus w² of the next is 1, so the variance stays the same
// across the seams and no block edge shows as a jump.
class Tachogram {
 public:
  Tachogram(const SyntheticEcgOptions& o, std::uint64_t seed)
      : rng_(seed, 1), rr_mean_(60 / o.mean_hr_bpm),
        rr_sd_(60 * o.hr_std_bpm / (o.mean_hr_bpm * o.mean_hr_bpm)) {
    build_spectrum(o);
  }

  double mean() const { return rr_mean_; }

  // RR interval (s) at time t ≥ 0. Calls must come with non-decreasing t: the blocks before
  // the one t is in are forgotten (two blocks of ~60 terms are all that is kept).
  double rr_at(double t) {
    // Block b spans [(b − 1)·hop, (b + 1)·hop); t lies in blocks m and m + 1.
    const auto m = static_cast<std::int64_t>(std::floor(t / kHopS));
    while (first_ + static_cast<std::int64_t>(blocks_.size()) < m + 2) blocks_.push_back(random_block());
    while (first_ < m) {
      blocks_.pop_front();
      ++first_;
    }
    const double dev = evaluate(blocks_[0], t - static_cast<double>(m - 1) * kHopS) +
                       evaluate(blocks_[1], t - static_cast<double>(m) * kHopS);
    // A very large SD could make an interval absurdly short; ECGSYN does not guard this.
    return std::max(rr_mean_ + dev, std::max(0.25 * rr_mean_, 0.2));
  }

 private:
  struct Term {
    int k;
    double c, s;  // Ak cos φk and Ak sin φk, scaled to the RR SD
  };

  void build_spectrum(const SyntheticEcgOptions& o) {
    // Power of bin k: ratio·G(f − lf) + 1·G(f − hf), G a Gaussian of SD kPeakSdHz; its
    // normalisation is common to both peaks and drops out. Bins below 1e-12 of the largest
    // (beyond ~7 SD of both peaks) are left out: about 60 terms remain.
    std::vector<double> power(kBins + 1, 0.0);
    double largest = 0;
    for (int k = 1; k <= kBins; ++k) {
      const double f = k / kBlockS;
      const double lf = (f - o.lf_hz) / kPeakSdHz, hf = (f - o.hf_hz) / kPeakSdHz;
      power[k] = o.lf_hf_ratio * std::exp(-0.5 * lf * lf) + std::exp(-0.5 * hf * hf);
      largest = std::max(largest, power[k]);
    }
    double variance = 0;
    for (int k = 1; k <= kBins; ++k) {
      if (power[k] < 1e-12 * largest) continue;
      bins_.push_back(k);
      amplitude_.push_back(std::sqrt(power[k]));
      variance += power[k] / 2;  // a cosine of amplitude A has mean square A²/2
    }
    // Random phases leave the variance of the sum exactly this: scale it to the RR SD.
    scale_ = variance > 0 ? rr_sd_ / std::sqrt(variance) : 0;
  }

  std::vector<Term> random_block() {
    std::vector<Term> terms(bins_.size());
    for (std::size_t i = 0; i < bins_.size(); ++i) {
      const double phi = kTwoPi * rng_.uniform();
      const double a = scale_ * amplitude_[i];
      terms[i] = {bins_[i], a * std::cos(phi), a * std::sin(phi)};
    }
    return terms;
  }

  // Cross-faded value of one block at u seconds from its start, 0 ≤ u < 512.
  static double evaluate(const std::vector<Term>& terms, double u) {
    double sum = 0;
    for (const Term& term : terms) {
      const double x = kTwoPi * term.k * u / kBlockS;
      sum += term.c * std::cos(x) - term.s * std::sin(x);
    }
    return std::sin(std::numbers::pi * u / kBlockS) * sum;
  }

  Rng rng_;
  double rr_mean_, rr_sd_, scale_ = 0;
  std::vector<int> bins_;
  std::vector<double> amplitude_;
  std::deque<std::vector<Term>> blocks_;  // blocks first_, first_ + 1
  std::int64_t first_ = 0;
};

// ---------------------------------------------------------------------------------------
// Morphology: the five events of the paper's Table 1 (θ rad, a, b rad), with ECGSYN's
// heart-rate scaling (widths × sqrt(hr/60), angles × (hr/60)^¼ or ^½), so that the QT
// interval shortens with the rate roughly as Bazett's formula says.

struct Morphology {
  std::array<double, 5> theta, a, b;
};

Morphology normal_morphology(double hr_bpm) {
  const double f = std::sqrt(hr_bpm / 60), f2 = std::sqrt(f);
  const double pi = std::numbers::pi;
  Morphology m{{-pi / 3, -pi / 12, 0, pi / 12, pi / 2},
               {1.2, -5.0, 30.0, -7.5, 0.75},
               {0.25, 0.1, 0.1, 0.1, 0.4}};
  const std::array<double, 5> angle_scale{f2, f, 1, f, f2};
  for (std::size_t i = 0; i < 5; ++i) {
    m.theta[i] *= angle_scale[i];
    m.b[i] *= f;
  }
  return m;
}

// A premature ventricular beat: no P wave, no Q, a wide tall R (twice the normal width), a
// broad S and a T wave opposite to the QRS. Amplitudes are chosen so that the R
// wave stays the largest deflection (the true R peak is the maximum): a wave's height goes
// as a·b², so 9 × 0.2² gives an R about 1.2 times the normal 30 × 0.1².
Morphology ectopic_morphology(double hr_bpm) {
  Morphology m = normal_morphology(hr_bpm);
  m.a = {0.0, 0.0, 9.0, -2.5, -1.2};
  m.b[2] *= 2;
  m.b[3] *= 2;
  m.theta[3] *= 1.8;
  return m;
}

// ---------------------------------------------------------------------------------------

struct Point {
  double x, y, z;
};

}  // namespace

struct SyntheticEcg::State {
  State(const SyntheticEcgOptions& o)
      : options(o), tachogram(o, o.seed), noise(o.seed, 2), ectopy(o.seed, 3),
        normal(normal_morphology(o.mean_hr_bpm)), ectopic(ectopic_morphology(o.mean_hr_bpm)),
        substeps(static_cast<int>(std::ceil(500 / o.fs))), h(1 / (o.fs * substeps)),
        ectopic_probability(o.ectopic_rate >= 0.5 ? 1.0 : o.ectopic_rate / (1 - o.ectopic_rate)),
        omega_ref(kTwoPi / tachogram.mean()) {
    omega = kTwoPi / tachogram.rr_at(0);
    calibrate();
    Rng wander(o.seed, 4);
    wander_phase = kTwoPi * wander.uniform();
    // z follows z0 through dz/dt = −(z − z0): a first-order low-pass. Drive it harder by the
    // inverse of its gain at the wander frequency so that the output swings ±baseline_wander_mv.
    const double w = kTwoPi * o.hf_hz;
    wander_z = o.baseline_wander_mv / mv_per_z * std::sqrt(1 + w * w);
  }

  // The event term of the paper's equation (3), with Δθi = θ − θi inside the current cycle
  // (θ ∈ (−π, π]), as in ECGSYN's C code: each cycle sees its own events only.
  static double event_drive(const Morphology& m, double theta) {
    double sum = 0;
    for (std::size_t i = 0; i < 5; ++i) {
      const double d = theta - m.theta[i];
      const double u = d / m.b[i];
      if (u * u < 60) sum += m.a[i] * d * std::exp(-0.5 * u * u);  // beyond: under 1e-13
    }
    return -sum;
  }

  // The paper's equations (3), with one change: the event term is multiplied by ω/ω̄ (ω̄ at
  // the mean RR), so it is identical at the mean rate and the rise and fall of each wave
  // cancel whatever ω does in between. Without it, an ectopic beat (ω jumps to 1/0.6 and then
  // 1/1.4 of normal at its R peak) leaves a baseline step of several tenths of a mV.
  Point derivative(const Point& p, double t, const Morphology& m) const {
    const double alpha = 1 - std::sqrt(p.x * p.x + p.y * p.y);
    const double theta = std::atan2(p.y, p.x);
    const double z0 = wander_z * std::sin(kTwoPi * options.hf_hz * t + wander_phase);
    return {alpha * p.x - omega * p.y, alpha * p.y + omega * p.x,
            omega / omega_ref * event_drive(m, theta) - (p.z - z0)};
  }

  Point rk4(const Point& p, double t, const Morphology& m) const {
    auto add = [](const Point& a, const Point& d, double s) {
      return Point{a.x + s * d.x, a.y + s * d.y, a.z + s * d.z};
    };
    const Point k1 = derivative(p, t, m);
    const Point k2 = derivative(add(p, k1, h / 2), t + h / 2, m);
    const Point k3 = derivative(add(p, k2, h / 2), t + h / 2, m);
    const Point k4 = derivative(add(p, k3, h), t + h, m);
    return {p.x + h / 6 * (k1.x + 2 * k2.x + 2 * k3.x + k4.x),
            p.y + h / 6 * (k1.y + 2 * k2.y + 2 * k3.y + k4.y),
            p.z + h / 6 * (k1.z + 2 * k2.z + 2 * k3.z + k4.z)};
  }

  // mV per unit of z: three noiseless normal beats at the mean rate, scaled so that the
  // third has ECGSYN's peak-to-peak. Uses the integrator itself, so the scale fits it.
  void calibrate() {
    const double saved_omega = omega, saved_wander = wander_z;
    omega = omega_ref;
    wander_z = 0;
    Point p{-1, 0, 0};
    const auto steps = static_cast<std::int64_t>(std::ceil(tachogram.mean() / h));
    double lo = 0, hi = 0;
    for (std::int64_t i = 0; i < 3 * steps; ++i) {
      p = rk4(p, 0, normal);
      if (i >= 2 * steps) lo = std::min(lo, p.z), hi = std::max(hi, p.z);
    }
    mv_per_z = kPeakToPeakMv / (hi - lo);
    omega = saved_omega;
    wander_z = saved_wander;
  }

  // Advances one internal step from time t, handling θ = ±π (the morphology of the next
  // cycle) and θ = 0 (a beat).
  void step(double t) {
    const double before = std::atan2(point.y, point.x);
    point = rk4(point, t, ectopic_cycle ? ectopic : normal);
    const double after = std::atan2(point.y, point.x);
    if (before > std::numbers::pi / 2 && after < -std::numbers::pi / 2) {
      ectopic_cycle = next_ectopic;
    } else if (before < 0 && after >= 0 && before > -std::numbers::pi / 2) {
      on_beat(t + h * (-before) / (after - before));
    }
  }

  // At the R peak: record it and set the angular speed until the next one.
  void on_beat(double t) {
    beats.push_back(static_cast<std::int64_t>(std::floor(t * options.fs + 0.5)));
    codes.push_back(ectopic_cycle ? 'V' : 'N');
    if (ectopic_cycle) {
      omega = kTwoPi / ((2 - kEctopicCoupling) * coupled_rr);
      next_ectopic = false;
      return;
    }
    const double rr = tachogram.rr_at(t);
    next_ectopic = ectopic_probability > 0 && ectopy.uniform() < ectopic_probability;
    if (next_ectopic) {
      coupled_rr = rr;
      omega = kTwoPi / (kEctopicCoupling * rr);
    } else {
      omega = kTwoPi / rr;
    }
  }

  std::int32_t sample_value() {
    double mv = mv_per_z * point.z;
    if (options.noise_mv > 0) mv += options.noise_mv * noise.normal();
    const double adu = std::floor(options.adc_zero + options.gain * mv + 0.5);
    constexpr double lo = std::numeric_limits<std::int32_t>::min();
    constexpr double hi = std::numeric_limits<std::int32_t>::max();
    return static_cast<std::int32_t>(std::clamp(adu, lo, hi));
  }

  void generate(std::size_t n, std::vector<std::int32_t>& out) {
    out.reserve(out.size() + n);
    for (std::size_t i = 0; i < n; ++i) {
      // Sample k is the state at k/fs; beats crossed on the way there get indices ≤ k.
      if (next_sample > 0) {
        for (int j = 0; j < substeps; ++j) {
          const double t = (static_cast<double>(next_sample - 1) +
                            static_cast<double>(j) / substeps) / options.fs;
          step(t);
        }
      }
      out.push_back(sample_value());
      ++next_sample;
    }
  }

  SyntheticEcgOptions options;
  Tachogram tachogram;
  Rng noise, ectopy;
  Morphology normal, ectopic;
  int substeps;
  double h;                    // internal step, s
  double ectopic_probability;  // per normal beat: the fraction of V beats is the option
  double omega_ref;            // rad/s at the mean RR
  double omega = 0;            // rad/s until the next R peak
  double mv_per_z = 1;
  double wander_z = 0, wander_phase = 0;
  double coupled_rr = 0;       // the RR an ectopic beat came early in
  bool ectopic_cycle = false, next_ectopic = false;
  Point point{-1, 0, 0};       // θ = π: diastole before the first beat
  std::int64_t next_sample = 0;
  std::vector<std::int64_t> beats;
  std::vector<char> codes;
};

// ---------------------------------------------------------------------------------------

namespace {

std::string number(double value) {
  std::ostringstream s;
  s << value;
  return s.str();
}

// Checks lo ≤ value ≤ hi (false for NaN) and writes the message for `name` otherwise.
bool in_range(const char* name, double value, double lo, double hi, std::string& error) {
  if (value >= lo && value <= hi) return true;
  error = std::string("synthetic ECG: option ") + name + " = " + number(value) +
          " is out of range [" + number(lo) + ", " + number(hi) + "]";
  return false;
}

// Checks lo < value ≤ hi.
bool in_open_range(const char* name, double value, double lo, double hi, std::string& error) {
  if (value > lo && value <= hi) return true;
  error = std::string("synthetic ECG: option ") + name + " = " + number(value) +
          " is out of range (" + number(lo) + ", " + number(hi) + "]";
  return false;
}

}  // namespace

Result<void> validate(const SyntheticEcgOptions& o) {
  std::string e;
  const bool ok = in_range("fs", o.fs, 50, 10000, e) &&
                  in_range("mean_hr_bpm", o.mean_hr_bpm, 30, 180, e) &&
                  in_range("hr_std_bpm", o.hr_std_bpm, 0, 0.2 * o.mean_hr_bpm, e) &&
                  in_range("lf_hf_ratio", o.lf_hf_ratio, 0, 1000, e) &&
                  in_range("hf_hz", o.hf_hz, 0.02, 0.8, e) &&
                  in_range("lf_hz", o.lf_hz, 0.02, o.hf_hz, e) &&
                  in_range("noise_mv", o.noise_mv, 0, 5, e) &&
                  in_range("baseline_wander_mv", o.baseline_wander_mv, 0, 5, e) &&
                  in_range("ectopic_rate", o.ectopic_rate, 0, 0.5, e) &&
                  in_open_range("gain", o.gain, 0, 1e6, e);
  if (!ok) return fail(e);
  if (o.lf_hz == o.hf_hz) {
    return fail("synthetic ECG: option lf_hz = " + number(o.lf_hz) + " must be below hf_hz");
  }
  return {};
}

Result<SyntheticEcg> SyntheticEcg::create(const SyntheticEcgOptions& options) {
  if (auto v = validate(options); !v) return fail(v.error().message);
  return SyntheticEcg(std::make_unique<State>(options));
}

SyntheticEcg::SyntheticEcg(std::unique_ptr<State> state) : state_(std::move(state)) {}
SyntheticEcg::SyntheticEcg(SyntheticEcg&&) noexcept = default;
SyntheticEcg& SyntheticEcg::operator=(SyntheticEcg&&) noexcept = default;
SyntheticEcg::~SyntheticEcg() = default;

void SyntheticEcg::generate(std::size_t n, std::vector<std::int32_t>& out) {
  state_->generate(n, out);
}

const std::vector<std::int64_t>& SyntheticEcg::beats() const { return state_->beats; }

std::vector<char> SyntheticEcg::beat_codes() const { return state_->codes; }

SyntheticBeats SyntheticEcg::take_beats() {
  SyntheticBeats taken{std::move(state_->beats), std::move(state_->codes)};
  state_->beats.clear();
  state_->codes.clear();
  return taken;
}

std::int64_t SyntheticEcg::samples_generated() const { return state_->next_sample; }

const SyntheticEcgOptions& SyntheticEcg::options() const { return state_->options; }

Result<std::vector<std::int32_t>> synthetic_ecg(double seconds,
                                                const SyntheticEcgOptions& options) {
  std::string e;
  if (!in_range("seconds", seconds, 0, 86400, e)) return fail(e);
  auto generator = SyntheticEcg::create(options);
  if (!generator) return fail(generator.error().message);
  std::vector<std::int32_t> out;
  generator->generate(static_cast<std::size_t>(std::llround(seconds * options.fs)), out);
  return out;
}

}  // namespace tahvel::aggregation
