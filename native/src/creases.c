/* Meshes: face-average vertex normals, and robust mode's creases (the
 * dihedral angles of the edges with two faces).
 * Part of meshlab-sharp's native library (meshlab_sharp.h). */
#include "internal.h"

/* Whether face f, along its winding, goes from its corner lo straight to its corner hi
 * (corners_walk_up). */
static inline int walks_up(const int64_t *faces, int64_t f, int64_t lo, int64_t hi) {
    const int64_t *c = faces + 3 * f;
    return corners_walk_up(c[0], c[1], c[2], lo, hi);
}

/* Union-find over the faces with, per face, the parity of its winding against its
 * parent's (1: wound the other way round) and, per root, whether its set holds a cycle
 * of odd parity (a non-orientable part). */
typedef struct {
    int32_t *parent;
    uint8_t *parity, *odd;
} winding_sets;

/* The root of f's set; *par: f's winding against the root's. Halves the paths. */
static int32_t winding_find(winding_sets *w, int32_t f, uint8_t *par) {
    uint8_t acc = 0;
    while (w->parent[f] != f) {
        int32_t up = w->parent[f];
        if (w->parent[up] != up) { /* point f at its grandparent */
            w->parity[f] ^= w->parity[up];
            w->parent[f] = w->parent[up];
        }
        acc ^= w->parity[f];
        f = w->parent[f];
    }
    *par = acc;
    return f;
}

/* Faces f and g share an edge and are wound `flip` (1: opposite ways round). */
static void winding_join(winding_sets *w, int32_t f, int32_t g, uint8_t flip) {
    uint8_t pf, pg;
    int32_t rf = winding_find(w, f, &pf), rg = winding_find(w, g, &pg);
    if (rf == rg) {
        if ((pf ^ pg) != flip) w->odd[rf] = 1;
        return;
    }
    w->parent[rg] = rf;
    w->parity[rg] = pf ^ pg ^ flip;
    w->odd[rf] |= w->odd[rg];
}

/* ms_face_windings over the faces' incidence (ptr, inc: ms_vertex_faces'), which it
 * only reads. */
static int64_t windings_at(const int64_t *faces, int64_t m, int64_t n, const int64_t *ptr,
                           const int32_t *inc, uint8_t *flip) {
    memset(flip, 0, (size_t)m);
    if (m == 0) return 0;
    if (m >= ((int64_t)1 << 31)) return -1;
    winding_sets w = {NULL, NULL, NULL};
    int64_t unoriented = -1, cap = 0;
    int64_t *other = NULL;
    int32_t *lowest = NULL;
    uint8_t *base = NULL;
    /* each edge (a, b), a < b, with exactly two faces, at a: the faces of a's fan that
     * hold b, read from a table of each face's corners after and before a; first only
     * whether some two go the same way along their edge (none: a consistently wound
     * mesh, nothing to turn), then the parts joined */
    for (int join = 0; join < 2; join++) {
        int same_seen = 0;
        for (int64_t a = 0; a < n && !(same_seen && !join); a++) {
            const int32_t *fa = inc + ptr[a];
            const int64_t deg = ptr[a + 1] - ptr[a];
            if (2 * deg > cap) {
                cap = 4 * deg;
                int64_t *grown = (int64_t *)realloc(other, (size_t)cap * sizeof(int64_t));
                if (!grown) goto done;
                other = grown;
            }
            for (int64_t i = 0; i < deg; i++) {
                const int64_t *c = faces + 3 * (int64_t)fa[i];
                const int at = c[0] == a ? 0 : c[1] == a ? 1 : 2;
                other[2 * i] = c[(at + 1) % 3];     /* the face goes a -> other[2 i] */
                other[2 * i + 1] = c[(at + 2) % 3]; /* and other[2 i + 1] -> a */
            }
            for (int64_t i = 0; i < deg; i++)
                for (int k = 0; k < 2; k++) {
                    const int64_t b = other[2 * i + k];
                    if (b < a) continue;
                    int64_t count = 1, second = -1, seen = 0, up = 0;
                    for (int64_t j = 0; j < deg && !seen; j++) {
                        if (j == i || (other[2 * j] != b && other[2 * j + 1] != b)) continue;
                        seen = j < i;
                        count++;
                        second = j;
                        up = other[2 * j] == b;
                    }
                    if (seen || count != 2) continue;
                    /* the same way along the edge: wound opposite ways round */
                    const int same = (k == 0) == up;
                    same_seen |= same;
                    if (join) winding_join(&w, fa[i], fa[second], (uint8_t)same);
                }
        }
        if (!join && !same_seen) { /* consistently wound: no face turned */
            unoriented = 0;
            goto done;
        }
        if (!join) {
            w.parent = (int32_t *)malloc((size_t)m * sizeof(int32_t));
            w.parity = (uint8_t *)calloc((size_t)m, 1);
            w.odd = (uint8_t *)calloc((size_t)m, 1);
            if (!w.parent || !w.parity || !w.odd) goto done;
            for (int64_t f = 0; f < m; f++) w.parent[f] = (int32_t)f;
        }
    }
    /* each set's lowest face keeps its winding (faces in order: the first of its set
     * met); a set with an odd cycle keeps every face's */
    lowest = (int32_t *)malloc((size_t)m * sizeof(int32_t));
    base = (uint8_t *)malloc((size_t)m);
    if (!lowest || !base) goto done;
    for (int64_t f = 0; f < m; f++) lowest[f] = -1;
    unoriented = 0;
    for (int64_t f = 0; f < m; f++) {
        uint8_t par;
        const int32_t r = winding_find(&w, (int32_t)f, &par);
        if (w.odd[r]) {
            unoriented++;
            continue;
        }
        if (lowest[r] < 0) {
            lowest[r] = (int32_t)f;
            base[r] = par;
        }
        flip[f] = par ^ base[r];
    }
done:
    free(other);
    free(lowest);
    free(base);
    free(w.parent);
    free(w.parity);
    free(w.odd);
    return unoriented;
}

int64_t ms_face_windings_at(const int64_t *faces, int64_t m, int64_t n, const int64_t *ptr,
                            const int32_t *inc, uint8_t *flip) {
    return windings_at(faces, m, n, ptr, inc, flip);
}

int64_t ms_face_windings(const int64_t *faces, int64_t m, int64_t n, uint8_t *flip) {
    if (m == 0 || m >= ((int64_t)1 << 31)) return windings_at(faces, m, n, NULL, NULL, flip);
    int64_t *ptr = (int64_t *)malloc((size_t)(n + 1) * sizeof(int64_t));
    int32_t *inc = (int32_t *)malloc((size_t)(3 * m) * sizeof(int32_t));
    int64_t unoriented = -1;
    if (ptr && inc && !ms_vertex_faces(faces, m, n, ptr, inc))
        unoriented = windings_at(faces, m, n, ptr, inc, flip);
    free(ptr);
    free(inc);
    return unoriented;
}

/* Face-average normals exactly as normals.face_average_normals computes them with
 * numpy (same products, same order of the sums: corner 0 of every face in face order,
 * then corner 1, then corner 2): acc (n, 3) zero on entry; each face's unit normal
 * negated where ms_face_windings turns the face. Each face's normal is computed again for
 * each corner, which is faster than storing them (no fresh memory). */
int64_t ms_face_average_normals(const double *p, int64_t n, const int64_t *faces, int64_t m,
                                double zero, double *acc) {
    return ms_face_average_normals_at(p, n, faces, m, NULL, zero, acc);
}

int64_t ms_face_average_normals_at(const double *p, int64_t n, const int64_t *faces, int64_t m,
                                   const uint8_t *turned, double zero, double *acc) {
    uint8_t *flip = NULL;
    int64_t unoriented = 0;
    if (turned == NULL) {
        flip = (uint8_t *)malloc((size_t)(m > 0 ? m : 1));
        unoriented = flip ? ms_face_windings(faces, m, n, flip) : -1;
        turned = flip;
    }
    if (unoriented < 0) {
        free(flip);
        return -1;
    }
    for (int c = 0; c < 3; c++) {
        for (int64_t f = 0; f < m; f++) {
            double u[3];
            face_normal(p, faces, f, u);
            double *t = acc + 3 * faces[3 * f + c];
            if (turned[f]) { t[0] -= u[0]; t[1] -= u[1]; t[2] -= u[2]; }
            else { t[0] += u[0]; t[1] += u[1]; t[2] += u[2]; }
        }
    }
    free(flip);
    for (int64_t v = 0; v < n; v++) {
        double *t = acc + 3 * v;
        double nn = sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
        if (nn > zero) { t[0] /= nn; t[1] /= nn; t[2] /= nn; }
        else { t[0] = 0.0; t[1] = 0.0; t[2] = 0.0; }
    }
    return unoriented;
}

/* ------------------------------------------------------------ robust mode on meshes */

static int cmp_i64(const void *a, const void *b) {
    int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

/* creases.dihedral_angles without the angle: the edges (a, b), a < b, with exactly two
 * faces, sorted lexicographically, into out_edges (room for (3 m + 1) / 2 rows), and the dot
 * product u . v of the two faces' unit normals (face_normal; face order: the lower index
 * first) into out_dot. n * m must be below 2^63. Returns the number of edges, or -1 out
 * of memory. out_edges (3 m int64) first holds the sort keys: edge e is written at 2 e,
 * never past the keys still to read (each edge written took two keys). */
int64_t ms_two_face_edges(const double *p, const int64_t *faces, int64_t m, int64_t n,
                          int64_t *out_edges, double *out_dot) {
    /* ptr[v + 1]: where the keys of lower end v start, then (after the fill) end */
    int64_t *ptr = (int64_t *)calloc((size_t)n + 2, sizeof(int64_t));
    /* per lower end, the other end and the face as one key: hi * m + f */
    int64_t *key = out_edges;
    if (!ptr) return -1;
    for (int64_t f = 0; f < m; f++)
        for (int c = 0; c < 3; c++) {
            int64_t a = faces[3 * f + c], b = faces[3 * f + (c + 1) % 3];
            ptr[(a < b ? a : b) + 2]++;
        }
    for (int64_t v = 0; v < n; v++) ptr[v + 2] += ptr[v + 1];
    for (int64_t f = 0; f < m; f++)
        for (int c = 0; c < 3; c++) {
            int64_t a = faces[3 * f + c], b = faces[3 * f + (c + 1) % 3];
            int64_t lo = a < b ? a : b, hi = a < b ? b : a;
            key[ptr[lo + 1]++] = hi * m + f;
        }
    int64_t e = 0;
    for (int64_t v = 0; v < n; v++) {
        int64_t *it = key + ptr[v];
        int64_t k = ptr[v + 1] - ptr[v];
        /* sort by the other end, then the face: insertion sort for short lists, qsort
         * for long ones (a fan of many faces) */
        if (k > 32) qsort(it, (size_t)k, sizeof(int64_t), cmp_i64);
        else for (int64_t i = 1; i < k; i++) {
            int64_t x = it[i], j = i;
            for (; j > 0 && it[j - 1] > x; j--) it[j] = it[j - 1];
            it[j] = x;
        }
        for (int64_t i = 0; i < k;) {
            int64_t hi = it[i] / m, j = i + 1;
            while (j < k && it[j] / m == hi) j++;
            if (j - i == 2) {
                int64_t f0 = it[i] % m, f1 = it[i + 1] % m; /* read before edge e is written */
                double u[3], w[3];
                face_normal(p, faces, f0, u);
                face_normal(p, faces, f1, w);
                out_edges[2 * e] = v;
                out_edges[2 * e + 1] = hi;
                out_dot[e++] = edge_dot(u, w, walks_up(faces, f0, v, hi) == walks_up(faces, f1, v, hi));
            }
            i = j;
        }
    }
    free(ptr);
    return e;
}

int ms_vertex_faces(const int64_t *faces, int64_t m, int64_t n, int64_t *ptr, int32_t *inc) {
    int64_t *fill = (int64_t *)malloc((size_t)(n > 0 ? n : 1) * sizeof(int64_t));
    if (fill == NULL) return -1;
    memset(ptr, 0, (size_t)(n + 1) * sizeof(int64_t));
    for (int64_t k = 0; k < 3 * m; k++) ptr[faces[k] + 1]++;
    for (int64_t v = 0; v < n; v++) ptr[v + 1] += ptr[v];
    memcpy(fill, ptr, (size_t)n * sizeof(int64_t));
    for (int64_t k = 0; k < 3 * m; k++) inc[fill[faces[k]]++] = (int32_t)(k / 3);
    free(fill);
    return 0;
}

/* The two-face edges (a, b), a < b, of the vertices a in [a0, a1) of ms_vertex_faces'
 * lists, in the order both crease functions meet them: a increasing, then a's faces in
 * order, then the face's corners after a's; each edge where its first face lists it.
 * The dot product of its two faces' unit normals (face_normal, the lower face first, as
 * ms_two_face_edges) sorts it: turned (not >= 1), numbered from e, or flat (>= 1: an
 * angle of exactly 0, most of a mesh's edges), counted in *flat and not numbered. With
 * mask NULL, the turned edges' dot products into dot and the number of the first turned
 * edge of each vertex into estart (n + 1); else the vertices of the turned edges whose
 * angle[e] > threshold marked in mask. Returns the number after the last turned edge. A vertex's
 * faces and their two other corners are read once into a small table (a fan of more than
 * CREASE_FAN faces: read from faces). The face normals go through `cache` when not NULL
 * (normal_cache). */
enum { CREASE_FAN = 64 };

/* A direct-mapped cache of unit face normals (face_normal), NORMAL_CACHE entries indexed
 * by the face's low bits: each face serves up to three edges, met by at most two
 * vertices, and in a mesh whose faces and vertices are numbered along its surface these
 * come close together (the 1M-vertex benchmark mesh: about 2 M normals instead of 6 M). */
enum { NORMAL_CACHE = 8192 };
typedef struct {
    int64_t face; /* -1: empty */
    double u[3];
} cached_normal_t;

/* face f's unit normal into u, from the cache when it holds f (the same bits). */
static inline void normal_cache(cached_normal_t *cache, const double *p, const int64_t *faces,
                                int64_t f, double *u) {
    cached_normal_t *c = cache + (f & (NORMAL_CACHE - 1));
    if (c->face != f) {
        face_normal(p, faces, f, c->u);
        c->face = f;
    }
    u[0] = c->u[0]; u[1] = c->u[1]; u[2] = c->u[2];
}

static int64_t crease_walk(const double *p, const int64_t *faces, int64_t a0, int64_t a1,
                           const int64_t *ptr, const int32_t *inc, int64_t e, double *dot,
                           int64_t *estart, const double *angle, double threshold, uint8_t *mask,
                           cached_normal_t *cache, int64_t *flat) {
    int64_t other[2 * CREASE_FAN];
    for (int64_t a = a0; a < a1; a++) {
        if (estart != NULL) estart[a] = e;
        const int32_t *fa = inc + ptr[a];
        const int64_t deg = ptr[a + 1] - ptr[a];
        const int64_t local = deg <= CREASE_FAN;
        for (int64_t i = 0; local && i < deg; i++) {
            const int64_t *c = faces + 3 * (int64_t)fa[i];
            const int at = c[0] == a ? 0 : c[1] == a ? 1 : 2;
            other[2 * i] = c[(at + 1) % 3];
            other[2 * i + 1] = c[(at + 2) % 3];
        }
        for (int64_t i = 0; i < deg; i++) {
            int64_t corner[2];
            if (local) {
                corner[0] = other[2 * i];
                corner[1] = other[2 * i + 1];
            } else {
                const int64_t *c = faces + 3 * (int64_t)fa[i];
                const int at = c[0] == a ? 0 : c[1] == a ? 1 : 2;
                corner[0] = c[(at + 1) % 3];
                corner[1] = c[(at + 2) % 3];
            }
            for (int k = 0; k < 2; k++) {
                const int64_t b = corner[k];
                if (b < a) continue;
                int64_t count = 1, second = -1, seen = 0;
                for (int64_t j = 0; j < deg; j++) {
                    if (j == i) continue;
                    int has;
                    if (local) {
                        has = other[2 * j] == b || other[2 * j + 1] == b;
                    } else {
                        const int64_t *c = faces + 3 * (int64_t)fa[j];
                        has = c[0] == b || c[1] == b || c[2] == b;
                    }
                    if (!has) continue;
                    if (j < i) {
                        seen = 1;
                        break;
                    }
                    count++;
                    second = fa[j];
                }
                if (seen || count != 2) continue;
                double u[3], w[3];
                if (cache != NULL) {
                    normal_cache(cache, p, faces, fa[i], u);
                    normal_cache(cache, p, faces, second, w);
                } else {
                    face_normal(p, faces, fa[i], u);
                    face_normal(p, faces, second, w);
                }
                const double d = edge_dot(u, w, (k == 0) == walks_up(faces, second, a, b));
                if (d >= 1.0) {
                    if (flat != NULL) ++*flat;
                    continue;
                }
                if (mask == NULL) {
                    dot[e] = d;
                } else if (angle[e] > threshold) {
                    mask[a] = 1;
                    mask[b] = 1;
                }
                e++;
            }
        }
    }
    if (estart != NULL) estart[a1] = e;
    return e;
}

int64_t ms_crease_dots(const double *p, const int64_t *faces, int64_t n, const int64_t *ptr,
                       const int32_t *inc, double *dot, int64_t *estart, int64_t *flat) {
    /* without room for the cache (256 KB), each normal is computed where it is used */
    cached_normal_t *cache = (cached_normal_t *)malloc(NORMAL_CACHE * sizeof(cached_normal_t));
    for (int64_t k = 0; cache != NULL && k < NORMAL_CACHE; k++) cache[k].face = -1;
    *flat = 0;
    const int64_t e = crease_walk(p, faces, 0, n, ptr, inc, 0, dot, estart, NULL, 0.0, NULL, cache, flat);
    free(cache);
    return e;
}

void ms_crease_mask(const double *p, const int64_t *faces, int64_t n, const int64_t *ptr,
                    const int32_t *inc, const int64_t *estart, const double *angle, double threshold,
                    uint8_t *mask) {
    /* only the vertices with an edge above the threshold are walked again (their normals
     * computed again, to tell the turned edges from the flat ones) */
    for (int64_t a = 0; a < n; a++) {
        int64_t k = estart[a];
        while (k < estart[a + 1] && !(angle[k] > threshold)) k++;
        if (k < estart[a + 1])
            crease_walk(p, faces, a, a + 1, ptr, inc, estart[a], NULL, NULL, angle, threshold, mask,
                        NULL, NULL);
    }
}
