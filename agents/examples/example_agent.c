/* example_agent.c - a worked Tahvel agent in C, over the C API (tahvel/node/tahvel.h).
 *
 *   usage: example_agent DIR [--count N] [--idle SECONDS]
 *
 * Opens the node store in DIR as agent "example-c", subscribes to heart-rate observations and
 * classifies each one. Input (any agent may write it; the observation should be an IRI so that
 * a later item can refer to it, since blank nodes are local to their item):
 *
 *     <http://example.org/home1/obs/17> <https://w3id.org/tahvel#heartRate>
 *         "72"^^<http://www.w3.org/2001/XMLSchema#integer> .
 *
 * Output, one derived item per observation (Turtle with the node's standard prefixes):
 *
 *     _:c a tv:HeartRateClassification ;
 *         tv:heartRateClass "normal" ;                      "low" < 50 <= "normal" <= 100 < "high"
 *         prov:wasDerivedFrom <http://example.org/home1/obs/17> .
 *
 * The subscription is persistent (triples on the whiteboard): a restart finds the one an
 * earlier run wrote instead of adding another. Each item is acknowledged only after its derived
 * item is stored, so a crash in between delivers it again on restart (at least once).
 *
 * Stops after N items (--count), after SECONDS without input (--idle, default 10), or on
 * SIGINT/SIGTERM. Exit status: 0 when it stopped as asked, 143 when a process other than its
 * parent sent the SIGTERM (an operator's `kill PID`: its supervisor then starts it again,
 * tahvel_stop_exit_status()), 1 on a Tahvel error (printed on stderr), 2 on a usage error.
 */
/* The C API is C99; clock_gettime is POSIX, which strict C99 leaves out. */
#define _POSIX_C_SOURCE 200809L

#include <ctype.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "tahvel/node/tahvel.h"

#define AGENT_ID "example-c"
#define HEART_RATE "<https://w3id.org/tahvel#heartRate>"
#define TAKE_TIMEOUT_MS 1000

struct options {
  const char* dir;
  long count; /* 0: no limit */
  long idle_seconds;
  const char* bad; /* the argument that could not be parsed (NULL: DIR is missing) */
};

static int parse_options(int argc, char** argv, struct options* options) {
  int i;
  options->dir = NULL;
  options->count = 0;
  options->idle_seconds = 10;
  options->bad = NULL;
  for (i = 1; i < argc; ++i) {
    options->bad = argv[i];
    if ((strcmp(argv[i], "--count") == 0 || strcmp(argv[i], "--idle") == 0) && i + 1 < argc) {
      char* end = NULL;
      long value = strtol(argv[i + 1], &end, 10);
      if (*argv[i + 1] == '\0' || *end != '\0' || value < 0) return 0;
      if (argv[i][2] == 'c') options->count = value;
      else options->idle_seconds = value;
      ++i;
    } else if (argv[i][0] != '-' && options->dir == NULL) {
      options->dir = argv[i];
    } else {
      return 0;
    }
  }
  options->bad = NULL;
  return options->dir != NULL;
}

/* Prints the failed call, the status and the library's message; returns 1 (the exit status). */
static int report(const char* call, tahvel_status status) {
  fprintf(stderr, "example_agent: %s failed: %s (%s)\n", call, tahvel_strerror(status),
          tahvel_last_error());
  return 1;
}

/* "low", "normal" or "high" for a heart rate in beats per minute. */
static const char* classify(double bpm) {
  if (bpm < 50.0) return "low";
  if (bpm > 100.0) return "high";
  return "normal";
}

/* Writes the derived item for one heart-rate triple: `subject` is the observation's N-Triples
 * term, `object` the literal holding the rate. */
static tahvel_status derive(tahvel_agent* agent, const char* subject, const char* object) {
  char turtle[4096];
  double bpm;
  int n;
  char* end = NULL;
  if (object[0] != '"') return TAHVEL_OK; /* not a literal: nothing to classify */
  /* The whole lexical form a finite number ("abc", "NaN", "0x40" and " 72" are no heart rate):
   * else logged and skipped, as the pipeline's agents do with malformed input. */
  bpm = strtod(object + 1, &end);
  if (end == object + 1 || isspace((unsigned char)object[1]) || *end != '"' || !isfinite(bpm) || bpm < 0 || memchr(object + 1, 'x', (size_t)(end - object - 1)) ||
      memchr(object + 1, 'X', (size_t)(end - object - 1))) {
    fprintf(stderr, "example_agent: %s %s: not a heart rate, skipped\n", subject, object);
    return TAHVEL_OK;
  }
  if (subject[0] == '<') {
    n = snprintf(turtle, sizeof turtle,
                 "_:c a tv:HeartRateClassification ; tv:heartRateClass \"%s\" ;"
                 " prov:wasDerivedFrom %s .\n",
                 classify(bpm), subject);
  } else { /* a blank node: it cannot be named from another item */
    n = snprintf(turtle, sizeof turtle,
                 "_:c a tv:HeartRateClassification ; tv:heartRateClass \"%s\" .\n",
                 classify(bpm));
  }
  if (n < 0 || (size_t)n >= sizeof turtle) return TAHVEL_OK; /* absurdly long IRI: skip */
  printf("example_agent: %s %g bpm -> %s\n", subject, bpm, classify(bpm));
  return tahvel_store(agent, turtle, (size_t)n, TAHVEL_FORMAT_TURTLE, NULL, 0, NULL);
}

/* Derives from every heart-rate triple of an item given as N-Triples text (modified in place:
 * one triple per line, "S P O ." with S and P free of spaces). */
static tahvel_status process(tahvel_agent* agent, char* ntriples) {
  char* line = ntriples;
  while (line != NULL && *line != '\0') {
    char* next = strchr(line, '\n');
    char* predicate = strchr(line, ' ');
    if (next != NULL) *next++ = '\0';
    if (predicate != NULL &&
        strncmp(predicate + 1, HEART_RATE " ", sizeof HEART_RATE) == 0) {
      char* object = predicate + 1 + sizeof HEART_RATE;
      size_t len = strlen(object);
      tahvel_status status;
      if (len >= 2 && strcmp(object + len - 2, " .") == 0) object[len - 2] = '\0';
      *predicate = '\0';
      status = derive(agent, line, object);
      if (status != TAHVEL_OK) return status;
    }
    line = next;
  }
  return TAHVEL_OK;
}

static double monotonic_seconds(void) {
  struct timespec now;
  clock_gettime(CLOCK_MONOTONIC, &now);
  return (double)now.tv_sec + (double)now.tv_nsec / 1e9;
}

/* Takes, derives and acknowledges until asked to stop. Returns the exit status. */
static int run(tahvel_agent* agent, const struct options* options) {
  long done = 0;
  /* Measured, not counted in timeouts: a signal ends a wait early as a timeout does. */
  double last_input = monotonic_seconds();
  while (!tahvel_stop_signal_received() && (options->count == 0 || done < options->count)) {
    uint64_t item;
    char* text;
    tahvel_status status = tahvel_take(agent, TAKE_TIMEOUT_MS, &item, &text, NULL);
    if (status == TAHVEL_TIMEOUT) { /* nothing yet (or a signal): look again */
      if (monotonic_seconds() - last_input >= (double)options->idle_seconds) {
        fprintf(stderr, "example_agent: no input for %ld s, stopping\n", options->idle_seconds);
        break;
      }
      continue;
    }
    if (status != TAHVEL_OK) return report("tahvel_take", status);
    last_input = monotonic_seconds();
    status = process(agent, text);
    tahvel_free(text);
    if (status != TAHVEL_OK) return report("tahvel_store", status); /* not acked: redelivered */
    status = tahvel_ack(agent, item); /* only now: a crash before this delivers it again */
    if (status != TAHVEL_OK) return report("tahvel_ack", status);
    ++done;
  }
  fprintf(stderr, "example_agent: processed %ld item(s)\n", done);
  return tahvel_stop_exit_status();
}

int main(int argc, char** argv) {
  struct options options;
  tahvel_node* node = NULL;
  tahvel_agent* agent = NULL;
  tahvel_status status;
  int exit_status;

  if (!parse_options(argc, argv, &options)) {
    /* The cause last: a supervisor shows the last line of a failed program's log. */
    fprintf(stderr, "usage: example_agent DIR [--count N] [--idle SECONDS]\n");
    if (options.bad != NULL) fprintf(stderr, "example_agent: bad argument '%s'\n", options.bad);
    else fprintf(stderr, "example_agent: the node directory is missing\n");
    return 2;
  }
  tahvel_install_stop_signal_handlers();

  status = tahvel_node_open(options.dir, &node);
  if (status != TAHVEL_OK) return report("tahvel_node_open", status);
  status = tahvel_agent_open(node, AGENT_ID, &agent);
  if (status != TAHVEL_OK) {
    exit_status = report("tahvel_agent_open", status);
    tahvel_node_close(node);
    return exit_status;
  }
  fprintf(stderr, "example_agent: running as %s\n", tahvel_agent_iri(agent));

  tahvel_node_close(node); /* the agent handle keeps the store open by itself */
  /* Persistent and idempotent: a restart gets back the subscription an earlier run wrote. */
  if ((status = tahvel_subscribe(agent, NULL, HEART_RATE, NULL, NULL)) != TAHVEL_OK) {
    exit_status = report("tahvel_subscribe", status);
  } else {
    exit_status = run(agent, &options);
  }
  tahvel_agent_close(agent);
  return exit_status;
}
