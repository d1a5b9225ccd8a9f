// Synthetic ECG with known ground truth: the dynamical model of McSharry, Clifford, Tarassenko
// and Smith (IEEE TBME 50(3), 2003, "ECGSYN"). A point circles a limit cycle in the (x, y)
// plane at the angular speed 2π/RR of the current beat; as its angle θ passes the angles θi of
// the P, Q, R, S and T events, Gaussian terms push z up or down, and z is the ECG. The RR
// intervals come from a tachogram with a bimodal spectrum (Mayer waves, LF; respiratory sinus
// arrhythmia, HF) made by inverse DFT with random phases. On top: baseline wander at the
// respiratory frequency, white measurement noise and premature ventricular beats with a full
// compensatory pause. docs/ecgsyn.md has the model, the parameters and the choices made.
//
// What it is for: simulated homes (agents that stream 1-second chunks of a patient that does
// not exist) and tests of R-peak detection and HRV, where the true beat times are known.
//
// Determinism: for the same options (seed included) the samples and beats are identical
// whatever the chunk sizes passed to generate(), and across standard libraries (the random
// numbers are std::mt19937_64 turned into uniforms and normals by code of ours, never by
// std::*_distribution). Only the last bits of libm's exp/atan2/log/cos may differ between
// C libraries, which moves an output sample by one ADC unit at most, and very rarely.
//
// Long runs: the tachogram is made in blocks of 512 s and forgotten once passed, time is kept
// as an integer sample count, so hours and days run in constant memory and without drift —
// except the list of true beats, which the caller empties with take_beats().
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "tahvel/aggregation/error.h"

namespace tahvel::aggregation {

// Generator parameters. Each has a documented range; create() and synthetic_ecg() return an
// error naming the first option out of range (NaN is always out of range).
struct SyntheticEcgOptions {
  double fs = 360;             // sampling frequency, Hz, in [50, 10000]
  double mean_hr_bpm = 70;     // mean heart rate, beats/min, in [30, 180]
  double hr_std_bpm = 3;       // SD of the heart rate, beats/min, in [0, 0.2 × mean_hr_bpm];
                               // turned into the RR SD 60·hr_std/mean_hr² s as in ECGSYN
  double lf_hf_ratio = 0.5;    // LF power / HF power of the tachogram, in [0, 1000]
  double lf_hz = 0.1;          // centre of the LF (Mayer wave) peak, Hz; 0.02 ≤ lf < hf
  double hf_hz = 0.25;         // centre of the HF (respiratory) peak, Hz, ≤ 0.8; also the
                               // frequency of the baseline wander
  double noise_mv = 0.01;      // SD of white Gaussian measurement noise, mV, in [0, 5]
  double baseline_wander_mv = 0.05;  // amplitude of the baseline wander, mV, in [0, 5]
  double ectopic_rate = 0.0;   // fraction of beats that are premature ventricular (code 'V'),
                               // in [0, 0.5]; never two in a row (0.5 is bigeminy)
  double gain = 200;           // ADC units per mV, in (0, 1e6]
  int adc_zero = 1024;         // ADC value of 0 mV
  std::uint64_t seed = 1;      // any value; same seed, same ECG
};

// Checks every range listed above. Nothing else can fail.
Result<void> validate(const SyntheticEcgOptions& options);

// The true beats handed over by take_beats(): R-peak sample indices (absolute, 0 = first
// sample generated, increasing) and, at the same positions, 'N' (normal) or 'V' (ectopic).
struct SyntheticBeats {
  std::vector<std::int64_t> samples;
  std::vector<char> codes;
};

// A streaming generator for one lead. Move-only; not thread-safe (one per stream).
class SyntheticEcg {
 public:
  // Validates the options (errors as validate()) and sets the generator at t = 0, in the
  // diastole before the first beat.
  static Result<SyntheticEcg> create(const SyntheticEcgOptions& options);

  SyntheticEcg(SyntheticEcg&&) noexcept;
  SyntheticEcg& operator=(SyntheticEcg&&) noexcept;
  SyntheticEcg(const SyntheticEcg&) = delete;
  SyntheticEcg& operator=(const SyntheticEcg&) = delete;
  ~SyntheticEcg();

  // Appends the next n samples (ADC units: adc_zero + gain × mV, rounded, clamped to int32)
  // to out, and records the R peaks that fall in them. Never fails; n = 0 does nothing.
  // Cost: about 0.25 ms per second of ECG on one core (RK4 at ≥ 500 Hz), whatever fs.
  void generate(std::size_t n, std::vector<std::int32_t>& out);

  // Sample indices of the true R peaks (the sample nearest to the instant the trajectory
  // passes θ = 0) in the samples generated so far and not yet taken, increasing. Every index
  // is < samples_generated(). The reference is valid until the next non-const call.
  const std::vector<std::int64_t>& beats() const;
  // 'N' or 'V' for each entry of beats().
  std::vector<char> beat_codes() const;
  // Hands over beats() and beat_codes() and empties them; later beats keep absolute indices.
  SyntheticBeats take_beats();

  // Number of samples generated since create().
  std::int64_t samples_generated() const;
  // The options the generator was created with.
  const SyntheticEcgOptions& options() const;

 private:
  struct State;
  explicit SyntheticEcg(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

// Convenience: round(seconds × fs) samples from a fresh generator. seconds in [0, 86400];
// errors as validate(), or naming `seconds`.
Result<std::vector<std::int32_t>> synthetic_ecg(double seconds, const SyntheticEcgOptions& options);

}  // namespace tahvel::aggregation
