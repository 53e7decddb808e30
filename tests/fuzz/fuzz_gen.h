/* Deterministic generator and mutator of bad input (tests/fuzz).
 *
 * Every case is a pure function of (kind, index): a splitmix64 stream seeded
 * with both picks one of a few valid seeds (scene texts with the real keys,
 * small Gmsh meshes) and then 0..4 mutations, structural ones first (wrong
 * counts, duplicate tags, NaN coordinates, inverted tets, ...), then textual
 * ones (byte flips, truncation, deleted or duplicated lines, numbers
 * replaced by nan/inf/-1/1e308/2^31/2^63, wrong types, unknown keys). Case 0
 * of every 32 is left unmutated: it must be accepted, which keeps the seeds
 * honest. `test_fuzz --dump scene|gmsh INDEX` prints one case. */
#ifndef FUZZ_GEN_H
#define FUZZ_GEN_H

#include <stddef.h>
#include <stdint.h>

typedef struct fz_rng {
    uint64_t s;
} fz_rng;

fz_rng fz_rng_seed(uint64_t kind, uint64_t index);
uint64_t fz_next(fz_rng *r);
/* Uniform in [0, n) (n >= 1). */
uint32_t fz_below(fz_rng *r, uint32_t n);

/* Growable NUL-terminated text. */
typedef struct fz_buf {
    char *p;
    size_t n, cap;
} fz_buf;

void fz_buf_free(fz_buf *b);
void fz_printf(fz_buf *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

enum { FZ_KIND_SCENE = 1, FZ_KIND_GMSH = 2 };

/* Case `index` of each kind into out (replaced). Returns the number of
 * mutations applied (0: an unmutated seed, which must be accepted) and a
 * short description of them in what (may be NULL). */
int fz_scene_case(uint64_t index, fz_buf *out, char *what, size_t what_len);
int fz_gmsh_case(uint64_t index, fz_buf *out, char *what, size_t what_len);

#endif
