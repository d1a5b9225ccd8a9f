// The tv: vocabulary's terms; see vocabulary.h. One per line, sorted: the hygiene check
// (tests/hygiene/check_vocabulary.sh) reads this list and compares it with the terms the
// sources, deploy files and docs use.
#include "vocabulary.h"

#include <algorithm>
#include <array>
#include <iterator>
#include <vector>

namespace tahvel::cli {
namespace {

constexpr std::array kTerms = {
    std::string_view("BlankNodeLabel"),
    std::string_view("EcgChunk"),
    std::string_view("EcgRecording"),
    std::string_view("HeartRateClassification"),
    std::string_view("HeartRateVariability"),
    std::string_view("HrvTrend"),
    std::string_view("RPeaks"),
    std::string_view("RemoteQuery"),
    std::string_view("Room"),
    std::string_view("RoomEnvironment"),
    std::string_view("RrSeries"),
    std::string_view("SensingSubscription"),
    std::string_view("alert"),
    std::string_view("alertDirection"),
    std::string_view("answerChunk"),
    std::string_view("answerLast"),
    std::string_view("answerRecords"),
    std::string_view("answerTo"),
    std::string_view("area"),
    std::string_view("areaFloor"),
    std::string_view("areaSubscriber"),
    std::string_view("areaSubscription"),
    std::string_view("baseline"),
    std::string_view("childStoreId"),
    std::string_view("command"),
    std::string_view("computedAt"),
    std::string_view("context"),
    std::string_view("diskFreeBytes"),
    std::string_view("durationS"),
    std::string_view("emptyGapEnds"),
    std::string_view("endSample"),
    std::string_view("environment"),
    std::string_view("errorCode"),
    std::string_view("errorMessage"),
    std::string_view("exitStatus"),
    std::string_view("filters"),
    std::string_view("firstAssertedAt"),
    std::string_view("floor"),
    std::string_view("frameCount"),
    std::string_view("fromSample"),
    std::string_view("gain"),
    std::string_view("gapCount"),
    std::string_view("heartRate"),
    std::string_view("heartRateClass"),
    std::string_view("heldPredicate"),
    std::string_view("heldRecords"),
    std::string_view("hfMs2"),
    std::string_view("holdingsAt"),
    std::string_view("holds"),
    std::string_view("humidity"),
    std::string_view("humidityAt"),
    std::string_view("intervals"),
    std::string_view("invalidSample"),
    std::string_view("irregularPct"),
    std::string_view("lastAssertedAt"),
    std::string_view("lastExit"),
    std::string_view("lastSeen"),
    std::string_view("latest"),
    std::string_view("lead"),
    std::string_view("leadCalibration"),
    std::string_view("leadInvalidSample"),
    std::string_view("lfHf"),
    std::string_view("lfMs2"),
    std::string_view("light"),
    std::string_view("lightAt"),
    std::string_view("linkConflict"),
    std::string_view("linkLeft"),
    std::string_view("linkState"),
    std::string_view("loadDigest"),
    std::string_view("loadFile"),
    std::string_view("loinc"),
    std::string_view("maxAgeS"),
    std::string_view("meanHrBpm"),
    std::string_view("meanNnMs"),
    std::string_view("metric"),
    std::string_view("movement"),
    std::string_view("movementAt"),
    std::string_view("movementLevel"),
    std::string_view("nnCount"),
    std::string_view("object"),
    std::string_view("othersCount"),
    std::string_view("outboxDepth"),
    std::string_view("output"),
    std::string_view("pWaveGapEnds"),
    std::string_view("parent"),
    std::string_view("parentLastHeard"),
    std::string_view("parentStoreId"),
    std::string_view("peaks"),
    std::string_view("pid"),
    std::string_view("pnn50Pct"),
    std::string_view("predicate"),
    std::string_view("problem"),
    std::string_view("program"),
    std::string_view("programState"),
    std::string_view("programsAt"),
    std::string_view("quantity"),
    std::string_view("queryArea"),
    std::string_view("queryCascade"),
    std::string_view("queryFloor"),
    std::string_view("queryLimit"),
    std::string_view("queryObject"),
    std::string_view("queryPredicate"),
    std::string_view("querySince"),
    std::string_view("querySource"),
    std::string_view("querySubject"),
    std::string_view("queryTarget"),
    std::string_view("queryTimeout"),
    std::string_view("queryUnder"),
    std::string_view("queryUntil"),
    std::string_view("recording"),
    std::string_view("replayedFrom"),
    std::string_view("replyTo"),
    std::string_view("restarts"),
    std::string_view("rmssdMs"),
    std::string_view("robustSd"),
    std::string_view("room"),
    std::string_view("rrCount"),
    std::string_view("sampleDigest"),
    std::string_view("sampleFormat"),
    std::string_view("samples"),
    std::string_view("samplingRate"),
    std::string_view("sd1Ms"),
    std::string_view("sd2Ms"),
    std::string_view("sdnnMs"),
    std::string_view("senses"),
    std::string_view("sensorMaker"),
    std::string_view("sensorModel"),
    std::string_view("slopeHorizonS"),
    std::string_view("slopePerHour"),
    std::string_view("softwareVersion"),
    std::string_view("source"),
    std::string_view("startSample"),
    std::string_view("startedAt"),
    std::string_view("state"),
    std::string_view("stepSeconds"),
    std::string_view("stepSecondsInForce"),
    std::string_view("storeDataBytes"),
    std::string_view("storeMaxBytes"),
    std::string_view("storeUsedBytes"),
    std::string_view("subject"),
    std::string_view("subscriber"),
    std::string_view("takeStore"),
    std::string_view("temperature"),
    std::string_view("temperatureAt"),
    std::string_view("thresholdAbove"),
    std::string_view("thresholdPeriodS"),
    std::string_view("toSample"),
    std::string_view("unit"),
    std::string_view("uplinkRefusal"),
    std::string_view("uplinkState"),
    std::string_view("validTimeS"),
    std::string_view("windowEndS"),
    std::string_view("windowLengthS"),
    std::string_view("windowSeconds"),
    std::string_view("windowSecondsInForce"),
    std::string_view("windowStartS"),
    std::string_view("windows"),
    std::string_view("zAgainstOthers"),
};

// SOSA's terms (https://www.w3.org/TR/vocab-ssn/, the 2017 core and terms the 2023 edition
// adds), sorted: `forward` patterns name them as often as tv: ones. A deployment may use terms of
// a later edition, so only a near miss of one of these is warned of.
constexpr std::string_view kSosaTerms[] = {
    "ActuatableProperty", "Actuation", "Actuator", "FeatureOfInterest", "ObservableProperty", "Observation",
    "ObservationCollection", "Platform", "Procedure", "Result", "Sample", "Sampler", "Sampling", "Sensor",
    "actsOnProperty", "hasFeatureOfInterest", "hasMember", "hasOriginalSample", "hasResult", "hasSample",
    "hasSimpleResult", "hasUltimateFeatureOfInterest", "hosts", "isActedOnBy", "isFeatureOfInterestOf",
    "isHostedBy", "isObservedBy", "isResultOf", "isSampleOf", "madeActuation", "madeByActuator", "madeBySampler",
    "madeBySensor", "madeObservation", "madeSampling", "observedProperty", "observes", "phenomenonTime",
    "resultTime", "usedProcedure",
};

template <typename Terms>
std::optional<std::string_view> nearest_of(const Terms& terms, std::string_view local_name, std::size_t within) {
  std::optional<std::string_view> best;
  std::size_t best_edits = within + 1;
  for (std::string_view term : terms) {
    const std::size_t e = edit_distance(local_name, term);
    if (e < best_edits) best_edits = e, best = term;
  }
  return best;
}

}  // namespace

bool is_tahvel_term(std::string_view local_name) {
  return std::binary_search(kTerms.begin(), kTerms.end(), local_name);
}

std::optional<std::string_view> nearest_tahvel_term(std::string_view local_name) {
  return nearest_of(kTerms, local_name, 3);  // more than 3 edits away is another word, not a slip
}

std::optional<std::string_view> sosa_term_misspelt(std::string_view local_name) {
  if (std::binary_search(std::begin(kSosaTerms), std::end(kSosaTerms), local_name)) return std::nullopt;
  // Two edits, not three: a term of a later edition should not be taken for a slip.
  return nearest_of(kSosaTerms, local_name, 2);
}

}  // namespace tahvel::cli
