/* Contact history index: an open-addressing hash (linear probing) keyed by
 * the pair of grain ids, giving the pair's row in the history array (the
 * tangential springs, stored in neighbour-list order so that the time loop
 * reads them sequentially).
 *
 * Lifetime: the neighbour list owns the table. When the list is rebuilt,
 * every candidate pair is entered in a fresh table and its spring copied
 * from the previous list's row found through the previous table. Lookups,
 * inserts and deletions never happen inside the time loop, nothing is
 * allocated per step (the tables grow only at a rebuild that needs more
 * room), and threads never share a row. */
#ifndef DEM_HASH_H
#define DEM_HASH_H

#include <stdint.h>

#define DEM_HASH_EMPTY UINT64_MAX

typedef struct dem_hash {
    int cap;      /* power of two */
    int count;
    uint64_t *key;
    int *row;     /* row of the key in the history array */
} dem_hash;

static inline uint64_t dem_pair_key(int a, int b)
{
    uint32_t lo = (uint32_t)(a < b ? a : b), hi = (uint32_t)(a < b ? b : a);
    return ((uint64_t)lo << 32) | hi;
}

/* splitmix64's finaliser: spreads consecutive ids over the table */
static inline uint64_t dem_hash_mix(uint64_t k)
{
    k ^= k >> 30;
    k *= 0xbf58476d1ce4e5b9ULL;
    k ^= k >> 27;
    k *= 0x94d049bb133111ebULL;
    k ^= k >> 31;
    return k;
}

/* Asks the memory for key's home slot (its key and row), to be read soon:
 * a table of many pairs is larger than the caches, and its slots are
 * random by design. Always inlined: GCC 12 finds a function of prefetches
 * free of side effects and drops its calls. */
static inline __attribute__((always_inline)) void dem_hash_prefetch(const dem_hash *h, uint64_t key)
{
    if (h->cap > 0) {
        const uint32_t s = (uint32_t)dem_hash_mix(key) & ((uint32_t)h->cap - 1);
        __builtin_prefetch(h->key + s);
        __builtin_prefetch(h->row + s);
    }
}

/* The capacity dem_hash_reset gives an empty table for n keys. */
int dem_hash_cap_for(long n);
/* Empties the table, growing it to hold at least n keys at <= 50 % load. */
int dem_hash_reset(dem_hash *h, int n);
void dem_hash_free(dem_hash *h);
/* Slot of key, inserting it (row -1) when absent. */
int dem_hash_insert(dem_hash *h, uint64_t key);
/* Slot of key or -1. */
int dem_hash_find(const dem_hash *h, uint64_t key);

#endif
