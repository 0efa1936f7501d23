/* renderer/util/sequence.c: the Sobol' generator tables of sequence.h. */
#include "sequence.h"

/* Joe and Kuo's dimensions 2-4 (new-joe-kuo-6.21201): degree s, the polynomial's inner
 * coefficients a (x^s + a_1 x^(s-1) + ... + 1, a_1 the most significant bit) and the initial
 * odd m_1..m_s. */
static const struct { int s; uint32_t a; uint32_t m[3]; } JOE_KUO[3] = {
    {1, 0, {1, 0, 0}},
    {2, 1, {1, 3, 0}},
    {3, 1, {1, 3, 1}},
};

/* Column k of dimension d in the usual MSB-first form, v_k = m_k 2^(32 - k) (k from 1). */
static uint32_t direction_msb(int d, int k) {
    if (d == 0) return 1u << (32 - k);
    int s = JOE_KUO[d - 1].s;
    uint32_t a = JOE_KUO[d - 1].a;
    uint32_t v[33];
    for (int j = 1; j <= k; ++j) {
        if (j <= s) {
            v[j] = JOE_KUO[d - 1].m[j - 1] << (32 - j);
        } else {
            /* v_j = a_1 v_(j-1) ^ ... ^ a_(s-1) v_(j-s+1) ^ v_(j-s) ^ (v_(j-s) >> s) */
            uint32_t x = v[j - s] ^ (v[j - s] >> s);
            for (int q = 1; q < s; ++q)
                if ((a >> (s - 1 - q)) & 1u) x ^= v[j - q];
            v[j] = x;
        }
    }
    return v[k];
}

uint32_t sequence_direction(int d, int k) { return sequence_reverse_bits(direction_msb(d, k + 1)); }

/* Bit b of the shuffled index y (bit-reversed) is bit 31 - b of the index: nibble q of the
 * table covers y's bits 8 + 4q .. 11 + 4q. */
void sequence_tables_init(SobolTables *t) {
    for (int d = 0; d < 4; ++d)
        for (int q = 0; q < 6; ++q)
            for (uint32_t v = 0; v < 16; ++v) {
                uint32_t x = 0;
                for (int b = 0; b < 4; ++b)
                    if (v & (1u << b)) x ^= sequence_direction(d, 31 - (8 + 4 * q + b));
                t->nibble[d][q][v] = x;
            }
}
