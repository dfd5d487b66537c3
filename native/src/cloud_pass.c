/* The cloud pass: kNN, normals and projected distances at every scale, and
 * robust mode's statistics, per chunk of points.
 * Part of meshlab-sharp's native library (meshlab_sharp.h). */
#include "internal.h"
#include "knn.h"

/* The offsets q (k, 3) of one kNN list nb (k = mk[nscales - 1]) from the point pi, q_j =
 * p[nb[j].pos] - pi, their squared lengths d2 (k) = nb[j].d2, and on the way scale_means'
 * smean and sh2 of the prefixes mk (the same running sums, in the same order). */
static void offsets_means(const double *p, const double *pi, const cand_t *nb,
                          const int64_t *mk, int nscales, double *q, double *d2, double *smean,
                          double *sh2) {
    double sx = 0, sy = 0, sz = 0, h2 = 0;
    int64_t j = 0;
    for (int s = 0; s < nscales; s++) {
        int64_t m = mk[s];
        for (; j < m; j++) {
            const double *pj = p + 3 * nb[j].pos;
            double x = pj[0] - pi[0], y = pj[1] - pi[1], z = pj[2] - pi[2], dj = nb[j].d2;
            q[3 * j] = x; q[3 * j + 1] = y; q[3 * j + 2] = z;
            d2[j] = dj;
            sx += x; sy += y; sz += z;
            if (dj > h2) h2 = dj;
        }
        smean[3 * s] = sx / (double)m;
        smean[3 * s + 1] = sy / (double)m;
        smean[3 * s + 2] = sz / (double)m;
        sh2[s] = h2;
    }
}

#ifdef HAVE_AVX2_PATH
/* offsets_means with each offset's x, y, z in the lanes of one register (the 4th lane
 * 0, masked off p and smean; q has room for one more double): the same differences,
 * sums and quotients, lane by lane. */
__attribute__((target("avx2"))) static void offsets_means_avx2(const double *p,
                                                               const double *pi,
                                                               const cand_t *nb,
                                                               const int64_t *mk, int nscales,
                                                               double *q, double *d2,
                                                               double *smean, double *sh2) {
    const __m256i xyz = _mm256_setr_epi64x(-1, -1, -1, 0);
    __m256d vpi = _mm256_maskload_pd(pi, xyz), sum = _mm256_setzero_pd();
    double h2 = 0;
    int64_t j = 0;
    for (int s = 0; s < nscales; s++) {
        int64_t m = mk[s];
        for (; j < m; j++) {
            __m256d v = _mm256_sub_pd(_mm256_maskload_pd(p + 3 * nb[j].pos, xyz), vpi);
            double dj = nb[j].d2;
            _mm256_storeu_pd(q + 3 * j, v);
            d2[j] = dj;
            sum = _mm256_add_pd(sum, v);
            if (dj > h2) h2 = dj;
        }
        _mm256_maskstore_pd(smean + 3 * s, xyz, _mm256_div_pd(sum, _mm256_set1_pd((double)m)));
        sh2[s] = h2;
    }
}
#endif

/* offsets_means, on 4 lanes when avx2. */
static inline void offsets_means_on(const double *p, const double *pi, const cand_t *nb,
                                    const int64_t *mk, int nscales, double *q, double *d2,
                                    double *smean, double *sh2, int avx2) {
#ifdef HAVE_AVX2_PATH
    if (avx2) {
        offsets_means_avx2(p, pi, nb, mk, nscales, q, d2, smean, sh2);
        return;
    }
#endif
    (void)avx2;
    offsets_means(p, pi, nb, mk, nscales, q, d2, smean, sh2);
}

/* kNN of tree positions [begin, end) at k = max(ks) (knn_cursor_t), then what out asks
 * for (see cloud_out_t). Returns 0, or -1 out of memory. */
int ms_cloud_pdis(const double *p, const int64_t *orig, int64_t n, const double *box, int depth,
                  const int64_t *ks, int nscales, int gaussian, int64_t begin, int64_t end,
                  const cloud_out_t *out) {
    tree_t T = {p, orig, box, n, depth};
    int64_t kmax = ks[nscales - 1];
    knn_cursor_t cur;
    int cur_rc = knn_cursor_init(&cur, &T, kmax);
    const cand_t *nb = cur.h.c;
    double *q = (double *)malloc(((size_t)kmax * 3 + 1) * sizeof(double)); /* +1: see
                                                                                * offsets_means_avx2 */
    double *d2 = (double *)malloc((size_t)kmax * sizeof(double));
    pca_lanes_fn pca = pca_lanes();
    /* per scale: mean offset (3), normal (3), largest squared distance (1) */
    double *smean = (double *)malloc((size_t)nscales * 7 * sizeof(double));
    double *snrm = smean ? smean + 3 * nscales : NULL, *sh2 = smean ? smean + 6 * nscales : NULL;
    double *soa = (double *)malloc((size_t)kmax * 4 * sizeof(double));
    double *ws = (double *)malloc((size_t)kmax * PCA_LANES * sizeof(double)); /* weights */
    double *ell = (double *)malloc((size_t)nscales * 2 * sizeof(double)); /* l, then o */
    double *hs = (double *)malloc((size_t)kmax * 2 * sizeof(double));
    int64_t *order = (int64_t *)malloc((size_t)kmax * sizeof(int64_t));
    char *keep = (char *)malloc((size_t)kmax);
    const sheet_params_t sheet = sheet_params(out);
    int64_t *mk = (int64_t *)malloc((size_t)nscales * sizeof(int64_t));
    int rc = 0;
    if (cur_rc || !q || !d2 || !smean || !soa || !ws || !ell || !hs || !order || !keep || !mk) {
        rc = -1;
        goto done;
    }
    for (int64_t i = begin; i < end; i++) {
        const double *pi = p + 3 * i;
        knn_cursor_next(&cur, i);
        int64_t ci = orig[i], oi = out->tree_order ? i : ci; /* cleaned index, its row */
        if (out->idx != NULL) {
            for (int64_t j = 0; j < kmax; j++) out->idx[oi * kmax + j] = nb[j].idx;
        }
        if (out->near != NULL) { /* tree_order 2: a tree position (ms_isolated_tree) */
            const cand_t *c = kmax > 1 ? nb + 1 : NULL;
            out->near[oi] = (int32_t)(out->tree_order == 2 ? (c ? c->pos : i) : (c ? c->idx : ci));
        }
        if (out->kth_d2 != NULL) { /* tree_order 2: kth_idx a tree position too */
            const cand_t *c = nb + kmax - 1;
            out->kth_d2[oi] = c->d2;
            out->kth_idx[oi] = (int32_t)(out->tree_order == 2 ? c->pos : c->idx);
        }
        if (out->nth_d2 != NULL) {
            out->nth_d2[oi] = nb[kmax - 1 < out->isolated_nth ? kmax - 1 : out->isolated_nth].d2;
            out->ref_d2[oi] = nb[kmax - 1 < out->isolated_ref ? kmax - 1 : out->isolated_ref].d2;
        }
        if (out->pdis == NULL && out->relative == NULL && out->noise == NULL) continue;
        for (int s = 0; s < nscales; s++) mk[s] = ks[s];
        offsets_means_on(p, pi, nb, mk, nscales, q, d2, smean, sh2, sheet.avx2);
        /* known: how many of the largest scales have their normal from the sheet filter's
         * PCA (the largest scale's, and the next one's computed beside it): their lists
         * are the same when the filter keeps every neighbour */
        int known = 0, means = 1; /* means: smean and sh2 hold the lists' */
        int pdis_wanted = out->pdis != NULL || out->relative != NULL;
        if (out->sheet_gap > 0.0) {
            /* the largest scale's normal for the filter, and the next ones' beside it */
            known = !pdis_wanted ? 1 : nscales < PCA_LANES ? nscales : PCA_LANES;
            pca_scales(pca, q, d2, mk, smean, sh2, nscales - known, nscales, gaussian, ws,
                       snrm);
                       if (sheet_keep(q, d2, kmax, snrm + 3 * (nscales - 1), &sheet, hs, order, keep) > 0) {
                known = 0;
                means = 0;
                int64_t t = 0, s = 0;
                for (int64_t j = 0; j < kmax; j++) {
                    while (s < nscales && ks[s] == j) mk[s++] = t;
                    if (!keep[j]) continue;
                    q[3 * t] = q[3 * j]; q[3 * t + 1] = q[3 * j + 1]; q[3 * t + 2] = q[3 * j + 2];
                    d2[t] = d2[j];
                    t++;
                }
                while (s < nscales) mk[s++] = t;
            }
        }
        int64_t kk = mk[nscales - 1]; /* the list's length after the sheet filter */
        if (out->noise != NULL) {
            int64_t k0 = out->noise_k < kk ? out->noise_k : kk;
            out->noise[oi] = k0 >= 2 ? noise_ratio(q, k0) : 0.0;
        }
        if (out->relative != NULL) {
            local_scale_values(q, d2, kk, soa, sheet.avx2);
            local_scale_prefixes_on(soa, mk, nscales, ell, ell + nscales, sheet.avx2);
        }
        if (out->pdis == NULL && out->relative == NULL) continue;
        double score = 0.0;
        if (!means) scale_means(q, d2, mk, nscales, smean, sh2);
        /* the scales whose normals are still to do, PCA_LANES at a time */
        pca_scales(pca, q, d2, mk, smean, sh2, 0, nscales - known, gaussian, ws, snrm);
        for (int s = 0; s < nscales; s++) {
            const double *mean = smean + 3 * s, *nv = snrm + 3 * s;
            double pd = fabs(mean[0] * nv[0] + mean[1] * nv[1] + mean[2] * nv[2]);
            if (out->normals != NULL) {
                double *nrm = out->normals + 3 * (s * n + oi);
                nrm[0] = nv[0]; nrm[1] = nv[1]; nrm[2] = nv[2];
            }
            if (out->pdis != NULL) out->pdis[s * n + oi] = pd;
            if (out->relative != NULL) { /* min(x / l, 1) keeps a NaN, as np.minimum */
                double l = ell[s], r = l > 0 ? pd / l : 0.0, g = l > 0 ? ell[nscales + s] / l : 0.0;
                out->relative[s * n + oi] = r > 1.0 ? 1.0 : r;
                score += (g > 1.0 ? 1.0 : g) / (double)nscales;
            }
        }
        if (out->score != NULL) out->score[oi] = score;
    }
done:
    knn_cursor_free(&cur);
    free(q);
    free(d2);
    free(smean);
    free(soa);
    free(ws);
    free(ell);
    free(hs);
    free(order);
    free(keep);
    free(mk);
    return rc;
}

/* Rows [begin, end) of src (n rows of `bytes` bytes each, tree order) to their cleaned
 * positions in dst: row i to row orig[i] (the pass's tree_order outputs: rows of 8-byte
 * values, and the statistics' int32 indices). */
void ms_scatter_rows(const int64_t *orig, const void *src, int64_t bytes, int64_t begin,
                     int64_t end, void *dst) {
    if (bytes == 8) { /* one value a row: a plain copy, no memcpy call per row */
        const uint64_t *s = (const uint64_t *)src;
        uint64_t *d = (uint64_t *)dst;
        for (int64_t i = begin; i < end; i++) d[orig[i]] = s[i];
        return;
    }
    if (bytes == 4) {
        const uint32_t *s = (const uint32_t *)src;
        uint32_t *d = (uint32_t *)dst;
        for (int64_t i = begin; i < end; i++) d[orig[i]] = s[i];
        return;
    }
    const char *s = (const char *)src;
    char *d = (char *)dst;
    for (int64_t i = begin; i < end; i++) {
        memcpy(d + orig[i] * bytes, s + i * bytes, (size_t)bytes);
    }
}
