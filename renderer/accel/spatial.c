/* spatial.c - spatial splits (Stich, Friedrich & Dietrich 2009, "Spatial
 * splits in bounding volume hierarchies", "SBVH"): the node's box cut into
 * equal slabs per axis, every triangle clipped to the slabs it spans, and a
 * plane between slabs chosen by the same SAH sweep as the object split; the
 * partition then cuts the triangles that straddle the plane, unless moving
 * one whole to a side is cheaper. A cut triangle sits in several leaves.
 * Which nodes try them is build.c's choice (RtBvhSettings.spatial_*). */
#include "build_internal.h"

/* Cuts reference r at the plane x[axis] = pos: the boxes of the triangle's
 * parts on either side (its vertices there and its edges' crossings of the
 * plane), padded and clipped to r's box. A sphere keeps its box, cut at the
 * plane. A side the primitive does not reach comes back invalid. */
static void ref_split(const Builder *b, const Ref *r, int axis, float pos, Box *L, Box *R)
{
    const RtPrim *p = &b->prims[r->prim];
    if (p->id & RT_PRIM_SPHERE_BIT) {
        *L = r->box;
        *R = r->box;
    } else {
        const float(*v)[3] = b->verts[r->prim];
        box_empty(L);
        box_empty(R);
        for (int k = 0; k < 3; k++) {
            const float *a = v[k], *c = v[(k + 1) % 3];
            if (a[axis] <= pos)
                box_grow_pt(L, a);
            if (a[axis] >= pos)
                box_grow_pt(R, a);
            if ((a[axis] < pos && c[axis] > pos) || (a[axis] > pos && c[axis] < pos)) {
                float s = (pos - a[axis]) / (c[axis] - a[axis]), q[3];
                for (int i = 0; i < 3; i++)
                    q[i] = a[i] + s * (c[i] - a[i]);
                q[axis] = pos;
                box_grow_pt(L, q);
                box_grow_pt(R, q);
            }
        }
        if (box_valid(L))
            box_pad(L);
        if (box_valid(R))
            box_pad(R);
    }
    float pad = 1e-6f * fabsf(pos) + 1e-30f;
    if (L->hi[axis] > pos + pad)
        L->hi[axis] = pos + pad;
    if (R->lo[axis] < pos - pad)
        R->lo[axis] = pos - pad;
    box_clip(L, &r->box);
    box_clip(R, &r->box);
}

/* Grows bins k0..k1 (slab k between the planes lo + k/scale and
 * lo + (k+1)/scale on axis a) by the parts of triangle v in each slab,
 * clipped to the reference's box r: the vertices in the slab and the edges'
 * crossings of its planes. (Estimates for the SAH sweep; the partition cuts
 * with ref_split.) */
static void chop(const float (*v)[3], const Box *r, int a, float lo, float scale, int k0, int k1, Box *bins)
{
    Box part[BVH_MAX_BINS];
    for (int k = k0; k <= k1; k++)
        box_empty(&part[k]);
    int kv[3];
    for (int j = 0; j < 3; j++) {
        kv[j] = bin_of(v[j][a], lo, scale, k0, k1);
        box_grow_pt(&part[kv[j]], v[j]);
    }
    for (int j = 0; j < 3; j++) {
        int j2 = (j + 1) % 3;
        const float *p = v[j], *q = v[j2];
        int kp = kv[j], kq = kv[j2];
        if (kp > kq) {
            const float *t = p; p = q; q = t;
            int tk = kp; kp = kq; kq = tk;
        }
        float dpa = q[a] - p[a];
        for (int k = kp; k < kq; k++) {
            float plane = lo + (float)(k + 1) / scale, x[3];
            float t = dpa > 0.0f ? (plane - p[a]) / dpa : 0.0f;
            t = t < 0.0f ? 0.0f : (t > 1.0f ? 1.0f : t);
            for (int i = 0; i < 3; i++)
                x[i] = p[i] + t * (q[i] - p[i]);
            x[a] = plane;
            box_grow_pt(&part[k], x);
            box_grow_pt(&part[k + 1], x);
        }
    }
    for (int k = k0; k <= k1; k++) {
        box_clip(&part[k], r);
        if (box_valid(&part[k]))
            box_grow(&bins[k], &part[k]);
    }
}

/* Binned spatial split: nb equal slabs of the node's box bb per axis; a
 * reference is cut into every slab it spans and counted entering its first
 * and leaving its last. */
static void spatial_bins(const Builder *b, const Ref *refs, uint32_t i0, uint32_t i1, const Box *bb,
                         const float *scale, int nb, Bins *o)
{
    bvh_bins_empty(o, nb);
    for (int a = 0; a < 3; a++) {
        if (!(scale[a] > 0.0f))
            continue;
        for (uint32_t i = i0; i < i1; i++) {
            const int k0 = bin_of(refs[i].box.lo[a], bb->lo[a], scale[a], 0, nb - 1);
            const int k1 = bin_of(refs[i].box.hi[a], bb->lo[a], scale[a], k0, nb - 1);
            o->in[a][k0]++;
            o->out[a][k1]++;
            if (k0 == k1 || (b->prims[refs[i].prim].id & RT_PRIM_SPHERE_BIT))
                for (int k = k0; k <= k1; k++) {
                    Box part = refs[i].box;
                    part.lo[a] = k > k0 ? bb->lo[a] + (float)k / scale[a] : part.lo[a];
                    part.hi[a] = k < k1 ? bb->lo[a] + (float)(k + 1) / scale[a] : part.hi[a];
                    box_grow(&o->box[a][k], &part);
                }
            else
                chop(b->verts[refs[i].prim], &refs[i].box, a, bb->lo[a], scale[a], k0, k1, o->box[a]);
        }
    }
}

/* The cheapest slab plane of the node's box bb, into *best when it beats
 * the split there. */
void bvh_spatial_split(const Builder *b, const Ref *refs, uint32_t count, const Box *bb, int nb, Split *best)
{
    float scale[3];
    bvh_bin_scales(bb, nb, scale);
    Bins bins;
    bvh_bins_all(spatial_bins, b, refs, count, bb, scale, nb, &bins, NULL);
    for (int a = 0; a < 3; a++) {
        if (!(scale[a] > 0.0f))
            continue;
        Split s = *best;
        bvh_sweep(bins.box[a], bins.in[a], bins.out[a], nb, a, &s, 1);
        if (s.cost < best->cost) {
            *best = s;
            best->pos = bb->lo[a] + (float)(best->bin + 1) / scale[a];
        }
    }
}

/* Where reference r, straddling the plane, goes ("reference unsplitting"):
 * 0 cut in two (L and R), 1 whole to the left, 2 whole to the right. lb and
 * rb are the sides' boxes so far, nl_all and nr_all their counts with every
 * undecided reference on both. */
static int straddler_side(const Ref *r, const Box *L, const Box *R, const Box *lb, const Box *rb, float nl_all,
                          float nr_all)
{
    if (!box_valid(L))
        return 2;
    if (!box_valid(R))
        return 1;
    Box lu = *lb, ru = *rb, lc = *lb, rc = *rb;
    box_grow(&lu, &r->box);
    box_grow(&ru, &r->box);
    box_grow(&lc, L);
    box_grow(&rc, R);
    float cut = box_area(&lc) * nl_all + box_area(&rc) * nr_all;
    float to_l = box_area(&lu) * nl_all + box_area(rb) * (nr_all - 1.0f);
    float to_r = box_area(lb) * (nl_all - 1.0f) + box_area(&ru) * nr_all;
    if (to_l < cut && to_l <= to_r)
        return 1;
    if (to_r < cut)
        return 2;
    return 0;
}

/* Partitions refs by the spatial split s into left and right; a reference
 * that straddles the plane is cut in two, or goes whole to one side when
 * that is cheaper. Returns 0 when the split separates nothing, cuts every
 * reference, or would exceed the reference budget. */
int bvh_spatial_partition(Builder *b, const Ref *refs, uint32_t count, const Split *s, Ref *left, uint32_t *nl_out,
                          Ref *right, uint32_t *nr_out)
{
    int a = s->axis;
    Box lb, rb;
    box_empty(&lb);
    box_empty(&rb);
    uint32_t sure_l = 0, sure_r = 0;
    for (uint32_t i = 0; i < count; i++) {
        if (refs[i].box.hi[a] <= s->pos) {
            box_grow(&lb, &refs[i].box);
            sure_l++;
        } else if (refs[i].box.lo[a] >= s->pos) {
            box_grow(&rb, &refs[i].box);
            sure_r++;
        }
    }
    float nl_all = (float)(count - sure_r), nr_all = (float)(count - sure_l);
    uint32_t nl = 0, nr = 0;
    for (uint32_t i = 0; i < count; i++) {
        const Ref *r = &refs[i];
        if (r->box.hi[a] <= s->pos) {
            left[nl++] = *r;
            continue;
        }
        if (r->box.lo[a] >= s->pos) {
            right[nr++] = *r;
            continue;
        }
        Box L, R;
        ref_split(b, r, a, s->pos, &L, &R);
        const int side = straddler_side(r, &L, &R, &lb, &rb, nl_all, nr_all);
        if (side == 1) {
            left[nl++] = *r;
            box_grow(&lb, &r->box);
            nr_all -= 1.0f;
        } else if (side == 2) {
            right[nr++] = *r;
            box_grow(&rb, &r->box);
            nl_all -= 1.0f;
        } else {
            left[nl] = *r;
            left[nl++].box = L;
            right[nr] = *r;
            right[nr++].box = R;
            box_grow(&lb, &L);
            box_grow(&rb, &R);
        }
    }
    /* (a split that cuts every reference only doubles them) */
    if (nl == 0 || nr == 0 || (nl == count && nr == count) || nl + nr - count > b->refs_left)
        return 0;
    b->refs_left -= nl + nr - count;
    *nl_out = nl;
    *nr_out = nr;
    return 1;
}
