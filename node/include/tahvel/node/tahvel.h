/* tahvel.h - the C API of a Tahvel whiteboard node, for small agents in any language.
 *
 * This header is the whole contract of the C API. It is a thin layer over the C++ library
 * (tahvel/node/node.h): same store, same error set, same deliver-once semantics. It compiles
 * alone as C99 or C++ and needs only <stddef.h> and <stdint.h>.
 *
 * A worked agent (error handling shortened; see agents/examples/example_agent.c):
 *
 *     tahvel_node* node;  tahvel_agent* agent;  uint64_t sub, item;
 *     char* text;  size_t len;
 *     tahvel_node_open("state/home1", &node);
 *     tahvel_agent_open(node, "classifier", &agent);          IRI = node IRI + "/classifier"
 *     tahvel_subscribe(agent, NULL, "<https://w3id.org/tahvel#heartRate>", NULL, &sub);
 *     for (;;) {
 *         tahvel_status st = tahvel_take(agent, 1000, &item, &text, &len);
 *         if (st == TAHVEL_TIMEOUT) continue;                  nothing yet (or a signal): look again
 *         if (st != TAHVEL_OK) break;                          tahvel_last_error() says why
 *         ... read `text` (N-Triples), tahvel_store(agent, ...) what you derive ...
 *         tahvel_free(text);
 *         tahvel_ack(agent, item);                             only now is it gone for good
 *     }
 *     tahvel_agent_close(agent);  tahvel_node_close(node);
 *
 * Handles. tahvel_node and tahvel_agent are opaque. Every function checks its handle: NULL, or
 * a handle that was already closed, gives TAHVEL_INVALID_ARGUMENT, never a crash (a closed
 * handle is recognised until the library hands out a new handle at the same address, so do not
 * rely on this for more than catching mistakes). An agent handle keeps the node's store open by
 * itself: it stays valid after tahvel_node_close() of the node it came from.
 *
 * Threads. A handle may be used by one thread at a time; different handles (also of the same
 * directory, and in different processes) may be used concurrently. Do not close a handle while
 * another thread is inside a call on it. tahvel_strerror() and tahvel_last_error() may be called
 * from any thread.
 *
 * Errors. Every function that can fail returns a tahvel_status: TAHVEL_OK (0) or a positive
 * code. On failure:
 *   - the store is unchanged: a failed write leaves nothing of its item behind;
 *   - every out-parameter has been set to NULL or 0 (so freeing it is always safe), except
 *     tahvel_watch's *bookmark_out, which keeps the bookmark given (to resume from);
 *   - tahvel_last_error() returns a one-line message naming the function, the cause and the
 *     place (line and column for syntax errors, the IRI for bad IRIs, the path for I/O).
 * No C++ exception ever leaves this API.
 *
 * Memory. Strings the caller must free are returned through `char**` out-parameters, are
 * NUL-terminated (the length out-parameter excludes the NUL), and are freed with tahvel_free().
 * Strings returned as `const char*` are owned by the library; each function says how long they
 * stay valid.
 *
 * Terms. Patterns take RDF terms in N-Triples syntax, one term per argument:
 *     "<http://example.org/x>"                                 an IRI
 *     "\"72\"^^<http://www.w3.org/2001/XMLSchema#integer>"     a typed literal
 *     "\"hello\""  "\"tere\"@et"                               plain and language-tagged literals
 *     "_:b12"                                                  a blank node, as the store
 *                                                              returned it
 * NULL (or "") matches any term. Surrounding spaces are ignored. Blank-node labels are renamed
 * when an item is stored (they are local to their item), so in tahvel_list() a blank node only
 * matches the label the store gave it, as seen in the output of tahvel_take() or tahvel_list();
 * subscriptions refuse blank nodes.
 *
 * Output text. tahvel_take() and tahvel_list() return N-Triples: one triple per line, each line
 * ending in " .\n", IRIs in angle brackets, xsd:string literals without a datatype.
 */
#ifndef TAHVEL_NODE_TAHVEL_H
#define TAHVEL_NODE_TAHVEL_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ------------------------------------------------------------------------------------------ */
/* Status codes. 1 to 11 have the values of tahvel::node::Errc in tahvel/node/error.h.         */

typedef enum tahvel_status {
  TAHVEL_OK = 0,                 /* success */
  TAHVEL_INVALID_ARGUMENT = 1,   /* a bad parameter: NULL or closed handle, NULL required
                                    out-parameter, bad format code, a term in the wrong
                                    position (a literal as subject), empty item, ... */
  TAHVEL_INVALID_IRI = 2,        /* an IRI that does not parse; message names the position */
  TAHVEL_SYNTAX = 3,             /* N-Triples/Turtle input error; message names line and column */
  TAHVEL_LITERAL_TOO_LARGE = 4,  /* a literal over the node's limit; message names the sizes */
  TAHVEL_STORE_FULL = 5,         /* the store reached its configured maximum size, or its
                                    disk has no room */
  TAHVEL_NOT_FOUND = 6,          /* no such node directory, item or record */
  TAHVEL_EXISTS = 7,             /* tahvel_node_init() of a directory that holds a store */
  TAHVEL_IO = 8,                 /* an operating-system error; message has the cause and path */
  TAHVEL_CORRUPT = 9,            /* the store's contents are not what this version wrote */
  TAHVEL_TIMEOUT = 10,           /* a wait ended without the awaited event (tahvel_take(),
                                    tahvel_take_as()) */
  TAHVEL_VERSION = 11,           /* the store was written by an incompatible format version */
  TAHVEL_NO_MEMORY = 100,        /* an allocation failed; nothing was changed */
  TAHVEL_INTERNAL = 101          /* an unexpected failure inside the library (a bug: please
                                    report the message of tahvel_last_error()) */
} tahvel_status;

/* Formats: input of tahvel_store() (N-Triples, Turtle); output of the *_as() reads
 * (N-Triples, or JSON: one object per line per record with its metadata — id, item, stored_at,
 * asserted_at, span when not 0, source, context, persistent — as `tahvel list --format json`
 * prints it). */
#define TAHVEL_FORMAT_NTRIPLES 1
#define TAHVEL_FORMAT_TURTLE 2
#define TAHVEL_FORMAT_JSON 3

/* Opaque handles. */
typedef struct tahvel_node tahvel_node;
typedef struct tahvel_agent tahvel_agent;

/* ------------------------------------------------------------------------------------------ */
/* Errors and memory                                                                          */

/* A short, static, English description of `status` ("no such node, item or record"), or
 * "unknown status" for a value outside the list above. Never NULL; never to be freed. */
const char* tahvel_strerror(tahvel_status status);

/* The message of the last failed call in the calling thread, e.g.
 *     "tahvel_store: <input>:2:42: line end in short string"
 * or "" when no call has failed in this thread yet. Successful calls do not clear it. The
 * string is owned by the library and stays valid until the next failing call in this thread.
 * TAHVEL_TIMEOUT from tahvel_take() counts as a failure here and sets a message too. */
const char* tahvel_last_error(void);

/* Frees a string the library returned (tahvel_take(), tahvel_take_as(), tahvel_list(),
 * tahvel_list_as(), tahvel_watch()). NULL is ignored. */
void tahvel_free(void* ptr);

/* ------------------------------------------------------------------------------------------ */
/* Nodes                                                                                      */

/* Opens the existing store in directory `dir` (every process of a node opens the same
 * directory) and sets *out to a new node handle, to be closed with tahvel_node_close().
 * Clears reader slots left by dead processes (a write that finds the map full clears them too).
 * Errors: TAHVEL_INVALID_ARGUMENT (dir or out NULL), TAHVEL_NOT_FOUND (no store in `dir`),
 * TAHVEL_IO, TAHVEL_CORRUPT, TAHVEL_VERSION, TAHVEL_NO_MEMORY. */
tahvel_status tahvel_node_open(const char* dir, tahvel_node** out);

/* Creates a new store in directory `dir` (created if missing) for the node whose IRI is `iri`
 * (absolute, e.g. "http://example.org/home1"), with the library's defaults: fast durability
 * (no fsync), no ring, literals up to 1 MiB, map up to 64 GiB. For other settings create the
 * store with the C++ API (Node::init) or the `tahvel` command. Sets *out to an open handle.
 * Errors: TAHVEL_INVALID_ARGUMENT, TAHVEL_EXISTS (`dir` already holds a store),
 * TAHVEL_INVALID_IRI, TAHVEL_IO, TAHVEL_NO_MEMORY. */
tahvel_status tahvel_node_init(const char* dir, const char* iri, tahvel_node** out);

/* Closes a node handle. Agent handles opened from it stay valid. NULL is ignored, as is a
 * handle that is already closed. */
void tahvel_node_close(tahvel_node* node);

/* The node's IRI. Owned by the handle, valid until tahvel_node_close(node). NULL for a NULL or
 * closed handle. */
const char* tahvel_node_iri(const tahvel_node* node);

/* Records matching the pattern (s, p, o: N-Triples terms or NULL for any; see "Terms" above),
 * read from one consistent snapshot of the whiteboard, as N-Triples text in *ntriples_out
 * (length in *len_out, may be NULL) that the caller frees with tahvel_free(). No match gives
 * TAHVEL_OK and an empty string.
 *   cascade: 0 returns the matches only; N also returns, for each match whose object is an IRI
 *            or blank node, the records with that object as subject, recursively to depth N.
 *            Each record appears once: the matches in the order they were stored, each followed
 *            by its sub-tree.
 *   limit:   at most this many triples in all; 0 for no limit.
 * A pattern with a bound s, p or o is answered through an index; all NULL scans every record.
 * Errors: TAHVEL_INVALID_ARGUMENT (handle or ntriples_out NULL, a literal as s, a non-IRI as p),
 * TAHVEL_SYNTAX (a term that does not parse, a relative IRI among them), TAHVEL_INVALID_IRI,
 * TAHVEL_IO, TAHVEL_CORRUPT, TAHVEL_NO_MEMORY. Errors of tahvel_list_as name it. */
tahvel_status tahvel_list(tahvel_node* node, const char* s, const char* p, const char* o,
                          unsigned cascade, size_t limit, char** ntriples_out, size_t* len_out);

/* As tahvel_list, in `format`: TAHVEL_FORMAT_NTRIPLES or TAHVEL_FORMAT_JSON (with metadata).
 * Errors: as tahvel_list, and TAHVEL_INVALID_ARGUMENT for another format. */
tahvel_status tahvel_list_as(tahvel_node* node, const char* s, const char* p, const char* o,
                             unsigned cascade, size_t limit, int format, char** text_out,
                             size_t* len_out);

/* Changes on the whiteboard after `bookmark` (0: from the beginning), oldest first, at most
 * `limit` (0: no limit), as JSON lines: an insertion is its record's object (its "id" is its
 * sequence number); a removal is the removed record's object led by "removed":true and its
 * "seq"; a change that cannot be read (a damaged record or log entry), or records the ring or a
 * time-to-live reclaimed before they were read (one change at the last of them, naming the
 * ids, and "reclaimed":true after "removed"), is {"seq":N,"removed":false|true,"unreadable":"why"}:
 * read the board again. Waits up to
 * `timeout_ms` (negative: without limit) for the first change when there is none yet (woken by
 * the writer's commit); a signal that runs a handler while it sleeps ends the wait as a timeout
 * does, so that a watcher sees its stop flag (one in the microseconds before it sleeps is not
 * seen until the wait ends: wait with a limit, as tahvel_take says). Sets *bookmark_out (may be NULL) to the last sequence
 * number returned, or to `bookmark` when none or on an error: pass it to the next call to resume
 * exactly.
 * The text (empty on timeout: TAHVEL_OK, not TAHVEL_TIMEOUT) is freed with tahvel_free().
 * Removals older than the last 65,536 are no longer reported.
 * Errors: TAHVEL_INVALID_ARGUMENT (a bad handle, or json_out NULL: the bookmark would move past
 * changes nobody saw), TAHVEL_IO, TAHVEL_CORRUPT, TAHVEL_NO_MEMORY. */
tahvel_status tahvel_watch(tahvel_node* node, uint64_t bookmark, int timeout_ms, size_t limit,
                           char** json_out, size_t* len_out, uint64_t* bookmark_out);

/* Removes every record of item `item` and, with cascade N, their sub-trees (as in tahvel_list).
 * The item is also removed from every input buffer it waits in, and from the nodes this node's
 * link sent it to, up or down (docs/protocol.md P7a, P10a). Sets *removed_out (may be NULL)
 * to the number of records removed.
 * Errors: TAHVEL_INVALID_ARGUMENT, TAHVEL_NOT_FOUND (no record of that item remains), TAHVEL_IO,
 * TAHVEL_STORE_FULL, TAHVEL_NO_MEMORY. */
tahvel_status tahvel_remove_item(tahvel_node* node, uint64_t item, unsigned cascade,
                                 uint64_t* removed_out);

/* ------------------------------------------------------------------------------------------ */
/* Agents                                                                                     */

/* Sets *out to a handle for agent `id` of the node: its IRI is the node IRI + "/" + id, and it
 * is the `source` of everything the handle stores (the store sets it; an agent cannot forge
 * it). The id is one IRI path segment of at most 200 bytes (files are named after ids):
 * non-empty, not "." or ".." (nor a percent-escaped
 * form of them) nor "*" (which addresses a node's whole subtree), in Unicode NFC, and without '/', '?', '#', whitespace, control characters or
 * the characters an IRI may not hold ('<', '>', '"', '{', '}', '|', '\\', '^', '`', '[', ']').
 * Spellings that name one IRI ("%41" and "A": a percent-escape of an unreserved ASCII
 * character, RFC 3986 6.2.2.2) are one agent; a percent-escaped non-ASCII character ("%C3%A9")
 * is not that character ("é"), as two RDF IRIs that differ so are two IRIs.
 * Opening a handle with the same id again (for example after a restart) gives the same input
 * buffer: items taken but not acknowledged by the previous handle are delivered again.
 * Close the handle with tahvel_agent_close(); it may outlive `node`.
 * Errors: TAHVEL_INVALID_ARGUMENT, TAHVEL_INVALID_IRI (bad id), TAHVEL_IO and TAHVEL_CORRUPT
 * (reading the node's prefixes), TAHVEL_NO_MEMORY. */
tahvel_status tahvel_agent_open(tahvel_node* node, const char* id, tahvel_agent** out);

/* Closes an agent handle. Items taken and not acknowledged stay in the input buffer and are
 * delivered again to the next handle of the same id. NULL or a closed handle is ignored. */
void tahvel_agent_close(tahvel_agent* agent);

/* The agent's IRI. Owned by the handle, valid until tahvel_agent_close(agent). NULL for a NULL
 * or closed handle. */
const char* tahvel_agent_iri(const tahvel_agent* agent);

/* Stores one item: the triples of `rdf` (`len` bytes, need not be NUL-terminated), written
 * together and atomically, with this agent as their source. The item lands in the agent's
 * output buffer, then in the shared store and in the input buffers of the agents whose
 * subscriptions match any of its triples, and those agents are woken.
 *   format:     TAHVEL_FORMAT_NTRIPLES or TAHVEL_FORMAT_TURTLE. Turtle input may use the
 *               node's prefixes (rdf, rdfs, xsd, owl, sosa, ssn, prov, geo, tv, and those added
 *               to the node) without declaring them; relative IRIs are errors (no base).
 *   context:    the IRI of the addressee or data group ("http://x/y" or "<http://x/y>"), or
 *               NULL or "" for none.
 *   persistent: nonzero: the item never expires by ring or time-to-live.
 * Blank nodes are local to the item and renamed. Sets *item_out (may be NULL) to the new item
 * id (monotonic per node). On any error nothing of the item is stored.
 * Errors: TAHVEL_INVALID_ARGUMENT (NULL handle, rdf NULL with len > 0, bad format, no triples),
 * TAHVEL_SYNTAX (message "<input>:LINE:COL: reason": also a relative IRI in the text, and bytes
 * that are not UTF-8, which the parser meets first), TAHVEL_INVALID_IRI (an IRI that parses as
 * RDF but breaks RFC 3987, or a bad context), TAHVEL_LITERAL_TOO_LARGE, TAHVEL_STORE_FULL,
 * TAHVEL_IO, TAHVEL_NO_MEMORY. */
tahvel_status tahvel_store(tahvel_agent* agent, const char* rdf, size_t len, int format,
                           const char* context, int persistent, uint64_t* item_out);

/* Subscribes the agent to the pattern (s, p, o: N-Triples terms or NULL for any; see "Terms"):
 * from now on every item stored on the node (by any agent, this one included) with at least
 * one triple matching the pattern lands in this agent's input buffer. An item lands there once
 * even when several of the agent's subscriptions match it.
 * The subscription is itself written on the whiteboard as a persistent item of triples
 *     _:x tv:subscriber <agent IRI> ; tv:subject S ; tv:predicate P ; tv:object O .
 * (only the bound positions), so it survives restarts of the agent. Calling tahvel_subscribe
 * again with the same pattern (an agent that restarts) adds nothing and gives back the existing
 * subscription's id. End one with tahvel_unsubscribe() (or tahvel_remove_item() of its id).
 * Sets *subscription_out (may be NULL) to the subscription's item id.
 * Errors: TAHVEL_INVALID_ARGUMENT (NULL handle, a literal as s, a non-IRI as p, a blank node
 * anywhere), TAHVEL_SYNTAX, TAHVEL_INVALID_IRI, TAHVEL_STORE_FULL, TAHVEL_IO, TAHVEL_NO_MEMORY. */
tahvel_status tahvel_subscribe(tahvel_agent* agent, const char* s, const char* p, const char* o,
                               uint64_t* subscription_out);

/* As tahvel_subscribe; a new subscription also puts into the input buffer, in the same
 * transaction, every item already on the node that it would have routed, oldest first: an
 * agent started after its input was written still gets all of it. Calling it again (the
 * subscription exists) delivers nothing more. Errors: as tahvel_subscribe. */
tahvel_status tahvel_subscribe_earlier(tahvel_agent* agent, const char* s, const char* p, const char* o,
                                       uint64_t* subscription_out);

/* Takes the oldest item from the agent's input buffer, waiting up to `timeout_ms` milliseconds
 * for one to arrive (woken by the writer's commit, no polling). timeout_ms 0 does not wait;
 * a negative timeout_ms waits without limit.
 * On success sets *item_out (may be NULL) to the item id and *ntriples_out (may be NULL) to the
 * whole item as it is now, as N-Triples text with *len_out (may be NULL) bytes, which the
 * caller frees with tahvel_free().
 *
 * TAKE DOES NOT ACKNOWLEDGE. The item stays at the head of the input buffer until
 * tahvel_ack(agent, item): until then every tahvel_take of this agent id (this handle, or a new
 * one after a restart) returns the same item again. Process the item first (store what you
 * derive from it), then acknowledge it: if the agent crashes in between, the item is delivered
 * again when it restarts. So delivery is at least once; an agent that must not repeat an
 * effect checks for it (e.g. by the prov:wasDerivedFrom link it wrote) before acting again.
 * Two processes that take as one agent id share one buffer: with manual acks both may take the
 * same head item before either acknowledges it. Run one process per agent id, or give each
 * worker an id of its own.
 * An item removed from the store before it was taken is skipped.
 *
 * Returns TAHVEL_TIMEOUT when no item arrived in time (out-parameters set to NULL/0), and also
 * when a signal that runs a handler arrived while it slept, SA_RESTART or not (tahvel_last_error
 * says "ended by a signal"; the kernel does not restart a wait with a time limit): an agent
 * whose SIGTERM handler sets a stop flag sees it at once. A signal in the microseconds between
 * the call and its sleep (reading the buffer) is not seen until the wait ends, so an agent that
 * stops on a signal waits with a limit (1000 ms, as the examples do) and checks its flag between
 * waits; without a limit it may wait for the next item. A loop that waits for items takes
 * TAHVEL_TIMEOUT as "look again".
 * Errors: TAHVEL_INVALID_ARGUMENT, TAHVEL_IO, TAHVEL_CORRUPT, TAHVEL_NO_MEMORY. */
tahvel_status tahvel_take(tahvel_agent* agent, int timeout_ms, uint64_t* item_out,
                          char** ntriples_out, size_t* len_out);

/* As tahvel_take, in `format`: TAHVEL_FORMAT_NTRIPLES or TAHVEL_FORMAT_JSON (each record with
 * its metadata: who wrote it, when, in which context).
 * Errors: as tahvel_take, and TAHVEL_INVALID_ARGUMENT for another format. */
tahvel_status tahvel_take_as(tahvel_agent* agent, int timeout_ms, int format, uint64_t* item_out,
                             char** text_out, size_t* len_out);

/* Sets *count_out to the number of items waiting in the agent's input buffer.
 * Errors: TAHVEL_INVALID_ARGUMENT, TAHVEL_IO. */
tahvel_status tahvel_pending(tahvel_agent* agent, uint64_t* count_out);

/* Ends one of the agent's subscriptions (the id tahvel_subscribe gave).
 * Errors: TAHVEL_INVALID_ARGUMENT, TAHVEL_NOT_FOUND (no such subscription of this agent),
 * TAHVEL_IO, TAHVEL_STORE_FULL. */
tahvel_status tahvel_unsubscribe(tahvel_agent* agent, uint64_t subscription);

/* Acknowledges `item`: removes it from the agent's input buffer, so it is not delivered again.
 * The item itself stays in the store, readable by everyone. Acknowledging an item that is not
 * in the buffer (acknowledged before, or never delivered) is not an error.
 * Errors: TAHVEL_INVALID_ARGUMENT, TAHVEL_IO, TAHVEL_NO_MEMORY. */
tahvel_status tahvel_ack(tahvel_agent* agent, uint64_t item);

/* ------------------------------------------------------------------------------------------ */
/* Stopping under a supervisor                                                                */

/* How an agent run by a supervisor (`tahvel up`) ends on SIGTERM and SIGINT, as Tahvel's own
 * programs do (tahvel/node/stop_signal.h): it stops cleanly in both cases, and its exit status
 * tells the supervisor whether the stop was asked for. A SIGTERM from its parent (the supervisor
 * stopping it, `tahvel down`) or a SIGINT (Ctrl-C) should end it with status 0; a SIGTERM from
 * anyone else (an operator's `kill PID`) with 143, 128 + SIGTERM. An agent that exits 0 on any
 * SIGTERM is taken for finished after a `kill PID`, and under the default restart policy (on
 * failure) never started again.
 *
 * tahvel_install_stop_signal_handlers() installs handlers for both signals (sigaction, without
 * SA_RESTART: a tahvel_take() in progress returns TAHVEL_TIMEOUT at the signal). Call it once,
 * early in main(), before any other thread starts. */
void tahvel_install_stop_signal_handlers(void);

/* Non-zero once SIGTERM or SIGINT has arrived since tahvel_install_stop_signal_handlers(): the
 * agent's loop checks it between takes and stops. */
int tahvel_stop_signal_received(void);

/* The exit status for an agent ending now: 143 after a SIGTERM sent by a process other than its
 * parent at the time the handlers were installed, else 0. */
int tahvel_stop_exit_status(void);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* TAHVEL_NODE_TAHVEL_H */
