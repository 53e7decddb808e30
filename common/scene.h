/* Scene files: one libconfig file describes both sides of a run.
 *
 * The reader is strict, as a user editing a scene by hand needs it to be:
 * every getter names the key and the file line when a value is missing, of
 * the wrong type or out of range; and cm_scene_check_unknown() reports every
 * key below a section that no getter asked for (a typo such as "dept" is an
 * error, not silently ignored).
 *
 * Paths use libconfig's syntax: "dem.bed.depth", "dem.layers.[1].radius".
 * Integers are accepted where a float is asked for (E = 50000000;). */
#ifndef CM_SCENE_H
#define CM_SCENE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "error.h"

typedef struct cm_scene cm_scene;

int cm_scene_open(const char *path, cm_scene **out, cm_error *err);
/* For tests and generated scenes: parse text; `name` is used in messages. */
int cm_scene_open_string(const char *text, const char *name, cm_scene **out, cm_error *err);
void cm_scene_close(cm_scene **s);

const char *cm_scene_path(const cm_scene *s);
/* Folder of the scene file, for resolving relative paths (mesh files, beds). */
const char *cm_scene_dir(const cm_scene *s);

bool cm_scene_has(cm_scene *s, const char *path);

/* Required values: a missing key is an error. Range is inclusive [lo, hi]. */
int cm_scene_double(cm_scene *s, const char *path, double lo, double hi, double *out, cm_error *err);
int cm_scene_int(cm_scene *s, const char *path, long lo, long hi, long *out, cm_error *err);
int cm_scene_string(cm_scene *s, const char *path, char *buf, size_t len, cm_error *err);
/* A fixed-length numeric array, e.g. gravity = [0.0, 0.0, -9.81]; */
int cm_scene_doubles(cm_scene *s, const char *path, int n, double lo, double hi, double *out, cm_error *err);
/* One of the listed words (NULL-terminated list); *out is its index. */
int cm_scene_choice(cm_scene *s, const char *path, const char *const *choices, int *out, cm_error *err);

/* Optional values: a missing key gives the default; a present one is checked. */
int cm_scene_double_opt(cm_scene *s, const char *path, double lo, double hi, double def, double *out, cm_error *err);
int cm_scene_int_opt(cm_scene *s, const char *path, long lo, long hi, long def, long *out, cm_error *err);
int cm_scene_bool_opt(cm_scene *s, const char *path, bool def, bool *out, cm_error *err);
int cm_scene_string_opt(cm_scene *s, const char *path, const char *def, char *buf, size_t len, cm_error *err);
int cm_scene_doubles_opt(cm_scene *s, const char *path, int n, double lo, double hi, const double *def,
                         double *out, cm_error *err);
int cm_scene_choice_opt(cm_scene *s, const char *path, const char *const *choices, int def, int *out,
                        cm_error *err);

/* Number of elements of a list or array at path (0 when absent). */
int cm_scene_length(cm_scene *s, const char *path);

/* Marks a whole section as known without reading it (a server skipping the
 * other server's section). */
void cm_scene_mark_known(cm_scene *s, const char *path);

/* The top-level sections of the programs that read one scene: `run` and
 * `coupling` (every program), `wheel` and `fem` (the FEM side, fem_server),
 * `dem` (dem_server), `scm` (scm_server). A program calls this with its own
 * NULL-terminated list before cm_scene_check_unknown: the other programs'
 * sections are then accepted unread, while a top-level name that no program
 * reads (a typo such as "wheeel") is still refused. */
void cm_scene_skip_foreign(cm_scene *s, const char *const *own);

/* Fails on the first key below any of the NULL-terminated `sections` that no
 * getter read, and on any top-level section not in `sections`. Call it after
 * all reading is done. */
int cm_scene_check_unknown(cm_scene *s, const char *const *sections, cm_error *err);

/* Writes the scene as it now stands (the file with every override applied)
 * in libconfig syntax: what `--print-config` prints, so that scripts read a
 * resolved scene instead of parsing libconfig and --set themselves. */
int cm_scene_write(const cm_scene *s, FILE *f, cm_error *err);
/* The same as JSON: groups are objects, arrays and lists are arrays, floats
 * always with a point or an exponent (1.0 stays a float) to 17 digits. What
 * scripts read (bench/post/runio.py), so that none parses libconfig. */
int cm_scene_write_json(const cm_scene *s, FILE *f, cm_error *err);
/* --print-config (json = 0) and --print-config=json (json = 1) of both
 * servers: opens the scene file (with the registered overrides), writes it to
 * f and closes it. */
int cm_scene_print_config(const char *path, int json, FILE *f, cm_error *err);

/* Overrides: "key.path=value", as given by `--set` on the command line, put
 * into the parsed tree before any getter reads it, so the strict readers see
 * an overridden scene exactly as if the file said so (an unknown key is still
 * refused, by cm_scene_check_unknown).
 *
 * The value is libconfig syntax (2e-5, 3, true, "newmark", [0.0, 0.1, 0.2]);
 * a bare word is a string. libconfig's arrays hold one scalar type: an
 * integer among floats ([10, 0.0, 0.0]) is taken as a float. A value that
 * does not parse is refused with libconfig's reason. An existing setting keeps its type where the value
 * fits it (dt=1 into a float key stays a float, name=run3 into a string key is
 * a string); otherwise the value's own type replaces it and the reader judges.
 * A missing key is created, with its missing parent groups. */
int cm_scene_set(cm_scene *s, const char *assignment, cm_error *err);

/* Process-wide list of overrides that cm_scene_open applies, in order, to
 * every scene file it opens (not cm_scene_open_string). A server's main()
 * registers its `--set` arguments here while parsing the command line; the
 * assignment string is kept by pointer (argv lives as long as the process).
 * Fails on a malformed assignment (no '=', empty key) or beyond
 * CM_SCENE_MAX_OVERRIDES. */
enum { CM_SCENE_MAX_OVERRIDES = 64 };
int cm_scene_add_override(const char *assignment, cm_error *err);
void cm_scene_clear_overrides(void);
/* Continues an FNV-1a 64 hash over the registered overrides, in order (a
 * checkpoint's scene hash covers the file and its --set arguments). */
uint64_t cm_scene_overrides_hash(uint64_t h);

#endif
