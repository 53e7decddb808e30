#include "dem_hash.h"

#include <stdlib.h>
#include <string.h>

int dem_hash_cap_for(long n)
{
    int want = 16;
    while (want < 2 * n + 16)
        want *= 2;
    return want;
}

int dem_hash_reset(dem_hash *h, int n)
{
    const int want = dem_hash_cap_for(n);
    if (want > h->cap) {
        uint64_t *k = realloc(h->key, (size_t)want * sizeof *k);
        if (!k)
            return -1;
        h->key = k;
        int *v = realloc(h->row, (size_t)want * sizeof *v);
        if (!v)
            return -1;
        h->row = v;
        h->cap = want;
    }
    memset(h->key, 0xff, (size_t)h->cap * sizeof *h->key);
    h->count = 0;
    return 0;
}

void dem_hash_free(dem_hash *h)
{
    free(h->key);
    free(h->row);
    memset(h, 0, sizeof *h);
}

int dem_hash_insert(dem_hash *h, uint64_t key)
{
    uint32_t m = (uint32_t)h->cap - 1;
    uint32_t s = (uint32_t)dem_hash_mix(key) & m;
    while (h->key[s] != DEM_HASH_EMPTY) {
        if (h->key[s] == key)
            return (int)s;
        s = (s + 1) & m;
    }
    h->key[s] = key;
    h->row[s] = -1;
    h->count++;
    return (int)s;
}

int dem_hash_find(const dem_hash *h, uint64_t key)
{
    if (h->cap == 0)
        return -1;
    uint32_t m = (uint32_t)h->cap - 1;
    uint32_t s = (uint32_t)dem_hash_mix(key) & m;
    while (h->key[s] != DEM_HASH_EMPTY) {
        if (h->key[s] == key)
            return (int)s;
        s = (s + 1) & m;
    }
    return -1;
}
