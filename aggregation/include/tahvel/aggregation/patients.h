// The patients a node's board knows of, as an operator at the hospital wants them at a glance
// (`tahvel patients`, docs/cli.md): per recording whose HRV windows reached the node, its
// latest window and, where tahvel-trend runs, the latest trend of each metric with its alert.
// Read from one snapshot; nothing is written.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "tahvel/aggregation/error.h"
#include "tahvel/aggregation/items.h"
#include "tahvel/node/node.h"

namespace tahvel::aggregation {

struct PatientView {
  std::string recording;             // the recording's IRI: one patient's ECG
  std::string source;                // the writer of its latest window (a home's <node>/hrv)
  std::size_t windows = 0;           // its HRV windows on the board, by that writer
  // Other agents that wrote windows of this recording under the same names as `source`, with
  // how many: there should be none (one tahvel-hrv per recording). Of writers that clash so, the
  // one whose node is nearest the recording (its IRI lies below that node) is shown, then the one
  // with more windows. Writers whose windows share no name (an agent renamed) are one series.
  std::vector<std::pair<std::string, std::size_t>> other_writers;
  // The readable window with the latest start that the record's end did not cut short
  // (cut_short); when every one was, the one that measured the longest.
  HrvWindowItem latest;
  std::int64_t latest_stored_ns = 0; // when that window was stored on this board
  // The signal time of its start (its records' asserted-at, ns since the epoch): with the
  // window's length, the --since and --until of a query for the raw ECG behind it.
  std::int64_t latest_asserted_ns = 0;
  // The node that computed it, where the raw ECG behind it lies: the writer's node (an agent's
  // IRI is its node's IRI + "/" + id). Empty when the writer's IRI has no path to strip.
  std::string source_node() const;
  // The newest recording of the same sensor (recording IRIs are <sensor>/recording/<name>; the
  // newest started last) when this one's windows stopped while that one's came: that one's
  // latest window starts more than one of this recording's windows after this one's latest, in
  // signal time (unless that one runs ahead of the clock: a replay at --speed 10), or none of
  // this one's windows was stored on the board since that one's first and that one went on
  // storing for more than two of this one's periods since this one's last.
  // This recording's source stopped, or started again as a new recording (a sensor restarted,
  // taken out of a deployment and put back). Its windows and alerts are of that earlier
  // recording. Empty when none is.
  std::string superseded_by;
  // Per metric, the trend update of the latest window that has one (tahvel-trend's items), in
  // the order of HrvMetric; empty where no trend agent runs.
  std::vector<TrendUpdate> trends;

  // A trend's change alert runs to its latest update.
  bool alerting() const;
  // The latest window holds no RR interval: no beats were found in it (a lead off, a flat line,
  // asystole). Its trend updates have no value and no alert of their own (docs/agents.md), so
  // an alert that ran up to it is not alerting() any more; the operator's view puts such a
  // patient with the alerting ones, since when the beats stop is when to look.
  bool no_beats() const;
  // The latest window's rhythm is too irregular for the RR-only NN rule (kIrregularPct): its
  // HRV may be off (docs/hrv.md, "Where the rule fails").
  bool irregular() const;
};

// Items of one writer that look like HRV windows or trends but cannot be read (a home of
// another version): counted, with the first reason, rather than left out unsaid.
struct UnreadableItems {
  std::string source;
  std::size_t count = 0;
  std::string first_error;
};

struct PatientsOnBoard {
  std::vector<PatientView> patients;       // alerting or without beats, not superseded, first; then by recording IRI
  std::vector<UnreadableItems> unreadable; // by writer IRI
};

// Every window's start and recording and every trend's recording, metric and start are read
// through the indexes; only each patient's latest window and latest trend per metric are read
// whole. Trend updates asserted before the earliest of the patients' latest windows (less
// 15 min) are read only for a patient that lacks a later one of a metric the board has (an
// update's asserted-at is taken to rise with its window's start, as tahvel-trend asserts it).
// With `since` (ns since the epoch), only windows and trend updates asserted then or later
// count: the chain asserts both at the signal time of the window (tahvel-hrv, tahvel-trend), so
// a patient is one with a window since then. Errors: those of the store.
Result<PatientsOnBoard> patients_on_board(const node::Snapshot& snapshot,
                                          std::optional<std::int64_t> since = std::nullopt);

}  // namespace tahvel::aggregation
