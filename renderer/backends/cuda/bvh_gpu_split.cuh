/* bvh_gpu_split.cuh - the GPU build's references: each record once, and
 * large triangles split into several (Karras and Aila, "Fast Parallel
 * Construction of High-Quality Bounding Volume Hierarchies", HPG 2013,
 * section 5). A triangle whose box is much larger than the triangle, and
 * above all one whose box crosses the coarse planes of the Morton grid,
 * spoils every node above it in a tree built from sorted codes; its pieces,
 * cut at those planes, sort with their neighbours instead. The budget is a
 * share of the records (RtBvhSettings.gpu_split); each triangle gets pieces
 * in proportion to its priority (X^i (A_box - 2 A_ideal))^(1/3), X = 2, i
 * the highest bit in which its box's corners' codes differ (their A_ideal
 * doubled: see k_split_priority). Included once by bvh_gpu.cu after
 * bvh_gpu_kernels.cuh. */
#ifndef RT_BVH_GPU_SPLIT_CUH
#define RT_BVH_GPU_SPLIT_CUH

#define SPLIT_MAX 256u /* pieces of one triangle: a 16x16 grid over one that spans the scene */
#define CLIP_MAX 9     /* a triangle clipped by six planes */

/* Record r's box into B.box[r] and its split priority into B.cost[r]
 * (both free until the leaves). */
__global__ void k_split_priority(Build B)
{
    const uint32_t r = blockIdx.x * blockDim.x + threadIdx.x;
    float p = 0.0f;
    if (r < B.nrec) {
        GBox b;
        record_box(B, r, b);
        B.box[r] = b;
        if (r >= B.nspheres) {
            const RtTriangle t = B.tris[r - B.nspheres];
            /* A flat triangle's own box has at least twice A_ideal, which no
             * split gains back (a floor of two triangles cut into pieces only
             * spreads it through the tree), so the excess counts from there. */
            const float ideal = rt_tri_ideal_area(B.verts[t.v[0]], B.verts[t.v[1]], B.verts[t.v[2]]);
            const uint32_t d = grid_code(B, b.lo) ^ grid_code(B, b.hi);
            const float excess = box_area(b) - 2.0f * ideal;
            GBox c;
            for (int k = 0; k < 3; k++)
                c.lo[k] = order_float((int)B.ctr[C_CMIN + k]), c.hi[k] = order_float((int)B.ctr[C_CMAX + k]);
            /* A triangle as large as the scene stays a cluster of its own near
             * the root; its pieces would join every object below it. */
            const bool huge = box_area(b) > 0.25f * box_area(c);
            if (excess > 0.0f && isfinite(excess) && !huge) /* (2^i under the root: no overflow) */
                p = exp2f((float)(d ? 32 - __clz(d) : 0) / 3.0f) * cbrtf(excess);
        }
        B.cost[r] = p;
    }
}

/* Each record's references: 1 plus its share of the budget. */
__global__ void k_split_count(Build B, const float *sum, uint32_t *count)
{
    const uint32_t r = blockIdx.x * blockDim.x + threadIdx.x;
    if (r >= B.nrec)
        return;
    const float s = *sum, share = s > 0.0f ? (float)B.budget * (B.cost[r] / s) : 0.0f;
    count[r] = 1u + (uint32_t)fminf(floorf(share), (float)(SPLIT_MAX - 1));
}

/* The references' count, after the exclusive sum of count into first. */
__global__ void k_split_total(Build B, const uint32_t *count, const uint32_t *first)
{
    B.ctr[C_REFS] = first[B.nrec - 1] + count[B.nrec - 1];
}

/* The bounds of triangle (p0, p1, p2) within box c, padded as record_box
 * pads and by the clipping's rounding; empty (lo > hi) where none of it is. */
__device__ static GBox clip_box(const float (*tri)[3], const GBox &c, float slack)
{
    float poly[2][CLIP_MAX][3];
    int n = 3, cur = 0;
    for (int i = 0; i < 3; i++)
        for (int k = 0; k < 3; k++)
            poly[0][i][k] = tri[i][k];
    for (int plane = 0; plane < 6 && n > 0; plane++) {
        const int k = plane >> 1, hi = plane & 1;
        const float at = hi ? c.hi[k] : c.lo[k];
        int m = 0;
        for (int i = 0; i < n; i++) {
            const float *a = poly[cur][i], *b = poly[cur][(i + 1) % n];
            const float da = hi ? at - a[k] : a[k] - at, db = hi ? at - b[k] : b[k] - at;
            if (da >= 0.0f && m < CLIP_MAX)
                for (int x = 0; x < 3; x++)
                    poly[1 - cur][m][x] = a[x];
            m += da >= 0.0f && m < CLIP_MAX;
            if ((da < 0.0f) != (db < 0.0f) && m < CLIP_MAX) {
                const float t = da / (da - db);
                for (int x = 0; x < 3; x++)
                    poly[1 - cur][m][x] = x == k ? at : a[x] + t * (b[x] - a[x]);
                m++;
            }
        }
        n = m, cur = 1 - cur;
    }
    GBox o;
    for (int k = 0; k < 3; k++)
        o.lo[k] = INFINITY, o.hi[k] = -INFINITY;
    for (int i = 0; i < n; i++)
        for (int k = 0; k < 3; k++)
            o.lo[k] = fminf(o.lo[k], poly[cur][i][k]), o.hi[k] = fmaxf(o.hi[k], poly[cur][i][k]);
    for (int k = 0; k < 3 && n > 0; k++) {
        const float pad = side_pad(o.lo[k], o.hi[k], slack);
        o.lo[k] = fmaxf(__fsub_rn(o.lo[k], pad), c.lo[k]);
        o.hi[k] = fminf(__fadd_rn(o.hi[k], pad), c.hi[k]);
    }
    return o;
}

__device__ static float box_extent(const GBox &b, int *axis)
{
    const float e[3] = {b.hi[0] - b.lo[0], b.hi[1] - b.lo[1], b.hi[2] - b.lo[2]};
    *axis = e[0] >= e[1] && e[0] >= e[2] ? 0 : e[1] >= e[2] ? 1 : 2;
    return e[*axis];
}

/* The plane that halves box b along axis k: the coarsest plane of the
 * Morton grid strictly inside it, else its middle. */
__device__ static float split_plane(const Build &B, const GBox &b, int k)
{
    const float lo = order_float((int)B.ctr[C_CMIN + k]), hi = order_float((int)B.ctr[C_CMAX + k]), e = hi - lo;
    if (e > 0.0f)
        for (int level = 1; level <= 10; level++) {
            const float cell = e / (float)(1 << level), at = lo + ceilf((b.lo[k] - lo) / cell) * cell;
            if (at > b.lo[k] && at < b.hi[k])
                return at;
        }
    return 0.5f * (b.lo[k] + b.hi[k]);
}

/* Reference i: its record r (the last whose first is at most i) and, for
 * the j-th of r's count[r] references, its piece: from r's box down, each
 * box cut at split_plane and the triangle clipped to either half, the
 * pieces shared in proportion to the halves' extents, until one is left.
 * A thread a reference, so a triangle cut into many pieces costs no one
 * thread more than the cuts above its piece. */
__global__ void k_split_emit(Build B, const uint32_t *count, const uint32_t *first)
{
    const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= B.ctr[C_REFS])
        return;
    uint32_t r = 0, hi = B.nrec - 1;
    while (r < hi) {
        const uint32_t mid = r + (hi - r + 1) / 2;
        if (first[mid] <= i)
            r = mid;
        else
            hi = mid - 1;
    }
    uint32_t j = i - first[r], c = count[r];
    GBox cur = B.box[r];
    if (c > 1) {
        const RtTriangle t = B.tris[r - B.nspheres];
        float tri[3][3], big = 0.0f;
        for (int v = 0; v < 3; v++) {
            const RtVec3 p = B.verts[t.v[v]];
            tri[v][0] = p.x, tri[v][1] = p.y, tri[v][2] = p.z;
            big = fmaxf(big, fmaxf(fabsf(p.x), fmaxf(fabsf(p.y), fabsf(p.z))));
        }
        const float slack = big * 0x1p-17f; /* 64 ulps of the largest coordinate: six clips' rounding */
        int shrink = 0;
        while (c > 1) {
            int k;
            if (!(box_extent(cur, &k) > 0.0f))
                break; /* a piece that cannot be cut: its copies */
            GBox lb = cur, rb = cur;
            lb.hi[k] = rb.lo[k] = split_plane(B, cur, k);
            lb = clip_box(tri, lb, slack);
            rb = clip_box(tri, rb, slack);
            const bool l = lb.lo[0] <= lb.hi[0], rr = rb.lo[0] <= rb.hi[0];
            if (l != rr && shrink++ < 32) { /* the plane cut only the pad: the piece's tighter box */
                cur = l ? lb : rb;
                continue;
            }
            if (!l || !rr)
                break;
            int kl, kr;
            const float el = box_extent(lb, &kl), er = box_extent(rb, &kr);
            uint32_t nl = (uint32_t)rintf((float)c * (el / (el + er)));
            nl = nl < 1u ? 1u : nl > c - 1u ? c - 1u : nl;
            if (j < nl) {
                cur = lb, c = nl;
            } else {
                cur = rb, c -= nl, j -= nl;
            }
        }
    }
    B.rbox[i] = cur;
    B.rrec[i] = r;
}

/* Without splits: reference r is record r; block 0 also sets the counters
 * (k_init's work, a launch fewer). */
__global__ void k_split_none(Build B)
{
    const uint32_t r = blockIdx.x * blockDim.x + threadIdx.x;
    if (blockIdx.x == 0)
        init_counter(B, threadIdx.x);
    if (r >= B.nrec)
        return;
    GBox b;
    record_box(B, r, b);
    B.rbox[r] = b;
    B.rrec[r] = r;
}

#endif
