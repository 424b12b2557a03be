/* bvh_gpu_kernels.cuh - the GPU build's device code (the steps bvh_gpu.cu
 * lists), included once by bvh_gpu.cu, whose host code launches it: the
 * build's state, the records' boxes and codes, H-PLOC, the 4-wide and
 * depth-first trees, the SAH cost and the slot order. */
#ifndef RT_BVH_GPU_KERNELS_CUH
#define RT_BVH_GPU_KERNELS_CUH

#define FULL 0xffffffffu
#define INVALID 0xffffffffu
#define COLLAPSED 0x80000000u /* meta: this node's subtree is one leaf */
#define PLOC_RADIUS 8         /* H-PLOC's search radius */
#define PLOC_KEEP 16          /* clusters a range keeps: half a warp */
#define MAX_LEVELS 64         /* of 4-wide nodes: more than the traversal's depth allows */
enum { BLOCK = 128, BLOCK_MAX = 1024 };

/* Counters and small results, one device array. */
enum { C_NODES, C_ROOT, C_PRIMS, C_QTAIL, C_DEPTH, C_LEAVES, C_NSUB, C_REFS, C_WDONE, C_CMIN, C_CMAX = C_CMIN + 3,
       C_MARK = C_CMAX + 3, C_COUNT = C_MARK + MAX_LEVELS + 2 };

struct GBox {
    float lo[3], hi[3];
};

struct Task {
    uint32_t node, wide, dfi, depth; /* binary node, its 4-wide node, its depth-first index and depth */
};

/* Device pointers of one build, passed by value to every kernel. */
struct Build {
    uint32_t n;        /* references (bvh_gpu_split.cuh): records and their pieces */
    uint32_t nrec, nspheres, budget; /* records (spheres first); pieces the splits may add */
    int leaf_max;
    const RtVec3 *verts;
    const RtTriangle *tris;
    const RtSphere *sph;
    GBox *rbox;        /* each reference's box */
    uint32_t *rrec;    /* each reference's record */
    GBox *box;         /* 2n-1 nodes: leaves 0..n-1 in Morton order, then the inner ones */
    uint2 *kids;       /* children; a leaf: (reference, INVALID) */
    float *cost;       /* SAH cost times the node's area */
    uint32_t *meta;    /* records below | COLLAPSED */
    uint32_t *nsub;    /* nodes below in the collapsed tree, itself included */
    uint32_t *cluster; /* H-PLOC: a range's clusters at its start, INVALID after them */
    uint32_t *order;   /* then (the same memory) each leaf slot's reference, in leaf order */
    uint32_t *parent;  /* H-PLOC: per split, the first child range to arrive */
    const uint32_t *skeys; /* sorted Morton codes */
    const uint32_t *svals; /* the records in their order */
    uint32_t *ctr;
    Task *queue;
    RtPrim *prims;
    RtBvhNode *bnodes;
    RtBvh4Node *wide;
};

/* ---------------------------------------------------------------- records */

/* The pad of a box's side lo..hi, as accel/build_internal.h's box_pad
 * computes it (no contraction into FMA: the pad must not shrink), plus
 * extra. */
__device__ static float side_pad(float lo, float hi, float extra)
{
    return __fadd_rn(__fmul_rn(1e-6f, __fadd_rn(fabsf(lo), fabsf(hi))), extra);
}

/* Record r's box, padded as the CPU pads it. */
__device__ static void record_box(const Build &B, uint32_t r, GBox &o)
{
    if (r < B.nspheres) {
        const RtSphere s = B.sph[r];
        for (int k = 0; k < 3; k++) {
            o.lo[k] = __fsub_rn(s.c[k], s.r);
            o.hi[k] = __fadd_rn(s.c[k], s.r);
        }
    } else {
        const RtTriangle t = B.tris[r - B.nspheres];
        const RtVec3 a = B.verts[t.v[0]], b = B.verts[t.v[1]], c = B.verts[t.v[2]];
        o.lo[0] = fminf(fminf(a.x, b.x), c.x), o.hi[0] = fmaxf(fmaxf(a.x, b.x), c.x);
        o.lo[1] = fminf(fminf(a.y, b.y), c.y), o.hi[1] = fmaxf(fmaxf(a.y, b.y), c.y);
        o.lo[2] = fminf(fminf(a.z, b.z), c.z), o.hi[2] = fmaxf(fmaxf(a.z, b.z), c.z);
    }
    for (int k = 0; k < 3; k++) {
        const float pad = side_pad(o.lo[k], o.hi[k], 1e-30f);
        o.lo[k] = __fsub_rn(o.lo[k], pad);
        o.hi[k] = __fadd_rn(o.hi[k], pad);
    }
}

/* Record r as the traversal reads it, with make_prims' arithmetic (accel/accel.c). */
__device__ static RtPrim record_prim(const Build &B, uint32_t r)
{
    RtPrim p;
    memset(&p, 0, sizeof p);
    if (r < B.nspheres) {
        const RtSphere s = B.sph[r];
        p.p0[0] = s.c[0], p.p0[1] = s.c[1], p.p0[2] = s.c[2];
        p.e1[0] = s.r;
        p.id = r | RT_PRIM_SPHERE_BIT;
    } else {
        const RtTriangle t = B.tris[r - B.nspheres];
        const RtVec3 a = B.verts[t.v[0]], b = B.verts[t.v[1]], c = B.verts[t.v[2]];
        p.p0[0] = a.x, p.p0[1] = a.y, p.p0[2] = a.z;
        p.e1[0] = __fsub_rn(b.x, a.x), p.e1[1] = __fsub_rn(b.y, a.y), p.e1[2] = __fsub_rn(b.z, a.z);
        p.e2[0] = __fsub_rn(c.x, a.x), p.e2[1] = __fsub_rn(c.y, a.y), p.e2[2] = __fsub_rn(c.z, a.z);
        p.id = r;
    }
    return p;
}

/* accel/build_internal.h's box_area. */
__device__ static float box_area(const GBox &b)
{
    const float dx = b.hi[0] - b.lo[0], dy = b.hi[1] - b.lo[1], dz = b.hi[2] - b.lo[2];
    if (dx < 0.0f || dy < 0.0f || dz < 0.0f)
        return 0.0f;
    return 2.0f * (dx * dy + dy * dz + dz * dx);
}

__device__ static GBox box_union(const GBox &a, const GBox &b)
{
    GBox u;
    for (int k = 0; k < 3; k++) {
        u.lo[k] = fminf(a.lo[k], b.lo[k]);
        u.hi[k] = fmaxf(a.hi[k], b.hi[k]);
    }
    return u;
}

/* Floats as ints in the same order, for atomicMin/atomicMax. */
__device__ static int float_order(float f)
{
    const int i = __float_as_int(f);
    return i >= 0 ? i : i ^ 0x7fffffff;
}
__device__ static float order_float(int i) { return __int_as_float(i >= 0 ? i : i ^ 0x7fffffff); }

/* Counter i's starting value (threads 0..C_COUNT-1 of one block). */
__device__ static void init_counter(const Build &B, uint32_t i)
{
    if (i < C_COUNT)
        B.ctr[i] = i == C_NODES ? B.n : i >= C_CMIN && i < C_CMAX ? 0x7fffffffu
                                   : i >= C_CMAX && i < C_CMAX + 3 ? 0x80000000u : 0u;
}

__global__ void k_init(Build B) { init_counter(B, threadIdx.x); }

/* The centroids' bounds, of the records or (refs) of the references: a
 * block's, over a grid of at most BOUNDS_BLOCKS, then one atomic per block
 * and axis (one per warp was 28K atomics on six words for 891K records:
 * 128 us, now the reads' time). */
enum { BOUNDS_BLOCKS = 1024 };
__global__ void k_bounds(Build B, bool refs)
{
    __shared__ float part[6][BLOCK_MAX / 32];
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    const uint32_t n = refs ? B.n : B.nrec, lane = threadIdx.x & 31u, warp = threadIdx.x >> 5;
    for (uint32_t i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
        GBox b;
        if (refs)
            b = B.rbox[i];
        else
            record_box(B, i, b);
        for (int k = 0; k < 3; k++) {
            const float c = 0.5f * (b.lo[k] + b.hi[k]);
            lo[k] = fminf(lo[k], c);
            hi[k] = fmaxf(hi[k], c);
        }
    }
    for (int k = 0; k < 3; k++)
        for (int s = 16; s > 0; s >>= 1) {
            lo[k] = fminf(lo[k], __shfl_xor_sync(FULL, lo[k], s));
            hi[k] = fmaxf(hi[k], __shfl_xor_sync(FULL, hi[k], s));
        }
    if (lane == 0)
        for (int k = 0; k < 3; k++)
            part[k][warp] = lo[k], part[3 + k][warp] = hi[k];
    __syncthreads();
    if (threadIdx.x == 0) {
        for (uint32_t w = 1; w < (blockDim.x + 31u) / 32u; w++)
            for (int k = 0; k < 3; k++)
                lo[k] = fminf(lo[k], part[k][w]), hi[k] = fmaxf(hi[k], part[3 + k][w]);
        if (lo[0] <= hi[0])
            for (int k = 0; k < 3; k++) {
                atomicMin((int *)&B.ctr[C_CMIN + k], float_order(lo[k]));
                atomicMax((int *)&B.ctr[C_CMAX + k], float_order(hi[k]));
            }
    }
}

/* 10 bits spread to every third of 30 (Karras 2012). */
__device__ static uint32_t spread10(uint32_t v)
{
    v = (v * 0x00010001u) & 0xFF0000FFu;
    v = (v * 0x00000101u) & 0x0F00F00Fu;
    v = (v * 0x00000011u) & 0xC30C30C3u;
    v = (v * 0x00000005u) & 0x49249249u;
    return v;
}

/* Point p's 30-bit code on the grid of the centroids' bounds (clamped to it). */
__device__ static uint32_t grid_code(const Build &B, const float p[3])
{
    uint32_t code = 0;
    for (int k = 0; k < 3; k++) {
        const float lo = order_float((int)B.ctr[C_CMIN + k]), hi = order_float((int)B.ctr[C_CMAX + k]);
        const float e = hi - lo, t = e > 0.0f ? (p[k] - lo) / e : 0.5f; /* (a flat axis: no 0/0) */
        code |= spread10((uint32_t)fminf(fmaxf(t * 1024.0f, 0.0f), 1023.0f)) << (2 - k);
    }
    return code;
}

__global__ void k_morton(Build B, uint32_t *keys, uint32_t *vals)
{
    const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= B.n)
        return;
    const GBox b = B.rbox[i];
    const float c[3] = {0.5f * (b.lo[0] + b.hi[0]), 0.5f * (b.lo[1] + b.hi[1]), 0.5f * (b.lo[2] + b.hi[2])};
    keys[i] = grid_code(B, c);
    vals[i] = i;
}

/* The leaves, in Morton order: each a cluster of its own. */
__global__ void k_leaves(Build B)
{
    const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= B.n)
        return;
    const uint32_t r = B.svals[i];
    const GBox b = B.rbox[r];
    B.box[i] = b;
    B.kids[i] = make_uint2(r, INVALID);
    B.cost[i] = box_area(b);
    B.meta[i] = 1u | COLLAPSED;
    B.nsub[i] = 1;
    B.cluster[i] = i;
    if (i + 1 < B.n)
        B.parent[i] = INVALID;
}

/* ---------------------------------------------------------------- H-PLOC */

/* A cluster as a lane holds it. */
struct Clu {
    uint32_t id;
    GBox b;
    float cost;
    uint32_t meta, nsub;
};

__device__ static void clu_load(const Build &B, uint32_t id, Clu &c)
{
    /* (L2 loads: another multiprocessor wrote these, before its fence) */
    const float *p = (const float *)&B.box[id];
    c.id = id;
    for (int k = 0; k < 3; k++) {
        c.b.lo[k] = __ldcg(p + k);
        c.b.hi[k] = __ldcg(p + 3 + k);
    }
    c.cost = __ldcg(&B.cost[id]);
    c.meta = __ldcg(&B.meta[id]);
    c.nsub = __ldcg(&B.nsub[id]);
}

__device__ static Clu clu_shfl(const Clu &c, int src)
{
    Clu o;
    o.id = __shfl_sync(FULL, c.id, src);
    for (int k = 0; k < 3; k++) {
        o.b.lo[k] = __shfl_sync(FULL, c.b.lo[k], src);
        o.b.hi[k] = __shfl_sync(FULL, c.b.hi[k], src);
    }
    o.cost = __shfl_sync(FULL, c.cost, src);
    o.meta = __shfl_sync(FULL, c.meta, src);
    o.nsub = __shfl_sync(FULL, c.nsub, src);
    return o;
}

/* The position of the k-th (from 0) set bit of m; 0 past the last. */
__device__ static uint32_t nth_set(uint32_t m, uint32_t k)
{
    if (k >= (uint32_t)__popc(m))
        return 0;
    uint32_t p = 0;
    for (int s = 16; s > 0; s >>= 1) {
        const uint32_t c = (uint32_t)__popc(m & ((1u << s) - 1u));
        if (k >= c) {
            k -= c;
            m >>= s;
            p += (uint32_t)s;
        }
    }
    return p;
}

/* Karras 2012's key augmentation: codes told apart by their positions. */
__device__ static uint64_t split_delta(const uint32_t *k, uint32_t i)
{
    return (((uint64_t)k[i] << 32) | i) ^ (((uint64_t)k[i + 1] << 32) | (i + 1));
}

/* The node merging clusters a and b (its id), with its SAH cost, collapsed
 * into a leaf of at most leaf_max records when that costs no more. */
__device__ static Clu make_node(const Build &B, const Clu &a, const Clu &b, uint32_t id)
{
    Clu c;
    c.id = id;
    c.b = box_union(a.b, b.b);
    const float area = box_area(c.b);
    const uint32_t cnt = (a.meta & ~COLLAPSED) + (b.meta & ~COLLAPSED);
    const float inner = area + a.cost + b.cost, leaf = area * (float)cnt;
    const bool col = cnt <= (uint32_t)B.leaf_max && leaf <= inner;
    c.cost = col ? leaf : inner;
    c.meta = cnt | (col ? COLLAPSED : 0u);
    c.nsub = col ? 1u : 1u + a.nsub + b.nsub;
    B.box[id] = c.b;
    B.kids[id] = make_uint2(a.id, b.id);
    B.cost[id] = c.cost;
    B.meta[id] = c.meta;
    B.nsub[id] = c.nsub;
    return c;
}

/* A pair's distance: the area of its union, then, for equal areas, the
 * nearer pair, the pair from an even position, the lower position -- one
 * order of all pairs, so the closest pair is always mutual and equal boxes
 * (400,000 copies of a triangle) pair off evenly instead of in a chain.
 * The low bits say which pair: its distance and lower lane. */
__device__ static uint64_t pair_key(float area, uint32_t lo, uint32_t dist)
{
    return ((uint64_t)__float_as_uint(area) << 32) | dist << 6 | (lo & 1u) << 5 | lo;
}

/* PLOC within a warp: lanes 0..n-1 hold clusters; merges mutual nearest
 * neighbours (pair_key) until at most `keep` are left. */
__device__ static uint32_t ploc_merge(const Build &B, Clu &c, uint32_t n, uint32_t keep, uint32_t lane)
{
    while (n > keep) {
        uint64_t best = ~0ull;
        for (int r = 1; r <= PLOC_RADIUS; r++) {
            GBox o;
            for (int k = 0; k < 3; k++) {
                o.lo[k] = __shfl_down_sync(FULL, c.b.lo[k], r);
                o.hi[k] = __shfl_down_sync(FULL, c.b.hi[k], r);
            }
            float a = INFINITY;
            if (lane + r < n) {
                GBox u = box_union(c.b, o);
                a = box_area(u);
                best = min(best, pair_key(a, lane, (uint32_t)r));
            }
            const float back = __shfl_up_sync(FULL, a, r); /* lane - r's area with this lane */
            if (lane >= (uint32_t)r && lane < n)
                best = min(best, pair_key(back, lane - r, (uint32_t)r));
        }
        const uint32_t lo = (uint32_t)best & 31u, nn = (lo == lane ? lo + ((uint32_t)best >> 6 & 15u) : lo) & 31u;
        const uint32_t back = __shfl_sync(FULL, (uint32_t)best, nn);
        const bool valid = lane < n, mutual = valid && back == (uint32_t)best, make = mutual && lane < nn;
        const uint32_t mk = __ballot_sync(FULL, make);
        uint32_t base = 0;
        if (lane == 0)
            base = atomicAdd(&B.ctr[C_NODES], (uint32_t)__popc(mk));
        base = __shfl_sync(FULL, base, 0);
        const Clu o = clu_shfl(c, (int)nn);
        if (make)
            c = make_node(B, c, o, base + (uint32_t)__popc(mk & ((1u << lane) - 1u)));
        const uint32_t km = __ballot_sync(FULL, valid && (!mutual || make));
        c = clu_shfl(c, (int)nth_set(km, lane));
        n = (uint32_t)__popc(km);
    }
    return n;
}

/* The clusters of range [l, r] split at s: up to 16 from each side's start,
 * into lanes 0..n-1; merged; the survivors back at the range's start. */
__device__ static void ploc_range(const Build &B, uint32_t l, uint32_t r, uint32_t s, bool fin, uint32_t lane)
{
    const uint32_t idx = lane < PLOC_KEEP ? l + lane : s + (lane - PLOC_KEEP);
    bool v = lane < PLOC_KEEP ? idx < s : idx <= r;
    const uint32_t id = v ? __ldcg(&B.cluster[idx]) : INVALID;
    v = v && id != INVALID;
    Clu c;
    memset(&c, 0, sizeof c);
    if (v)
        clu_load(B, id, c);
    const uint32_t vm = __ballot_sync(FULL, v);
    c = clu_shfl(c, (int)nth_set(vm, lane));
    const uint32_t n = ploc_merge(B, c, (uint32_t)__popc(vm), fin ? 1u : PLOC_KEEP, lane);
    if (fin) {
        if (lane == 0)
            B.ctr[C_ROOT] = c.id;
    } else if (lane < PLOC_KEEP) {
        B.cluster[l + lane] = lane < n ? c.id : INVALID;
    }
    __syncwarp();
    __threadfence(); /* (before the owner's next atomicExch publishes the range) */
}

__global__ void k_hploc(Build B)
{
    const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x, lane = threadIdx.x & 31u, n = B.n;
    uint32_t l = i, r = i, s = 0;
    bool active = i < n;
    while (__ballot_sync(FULL, active)) {
        if (active) {
            uint32_t prev;
            __threadfence();
            if (l == 0 || (r != n - 1 && split_delta(B.skeys, r) < split_delta(B.skeys, l - 1))) {
                prev = atomicExch(&B.parent[r], l); /* the left child: its sibling starts at r + 1 */
                if (prev != INVALID)
                    s = r + 1, r = prev;
            } else {
                prev = atomicExch(&B.parent[l - 1], r);
                if (prev != INVALID)
                    s = l, l = prev;
            }
            if (prev == INVALID)
                active = false; /* the sibling's thread goes on with the union */
            else
                __threadfence();
        }
        const bool fin = active && r - l + 1 == n;
        uint32_t wm = __ballot_sync(FULL, active && (r - l + 1 > PLOC_KEEP || fin));
        while (wm) {
            const int owner = __ffs(wm) - 1;
            wm &= wm - 1;
            ploc_range(B, __shfl_sync(FULL, l, owner), __shfl_sync(FULL, r, owner), __shfl_sync(FULL, s, owner),
                       __shfl_sync(FULL, fin, owner), lane);
        }
        if (fin)
            active = false;
    }
}

/* ---------------------------------------------------------------- 4-wide */

__device__ static void put_binary(const Build &B, uint32_t dfi, const GBox &b, uint32_t index, uint32_t meta)
{
    RtBvhNode o;
    for (int k = 0; k < 3; k++)
        o.lo[k] = b.lo[k], o.hi[k] = b.hi[k];
    o.index = index;
    o.meta = meta;
    B.bnodes[dfi] = o;
}

/* A collapsed subtree's references (at most leaf_max, so four levels) from
 * first on; k_prims writes their records. */
__device__ static void gather(const Build &B, uint32_t c, uint32_t first)
{
    uint32_t st[8], sp = 0, k = 0;
    st[sp++] = c;
    while (sp) {
        const uint32_t x = st[--sp];
        const uint2 kk = B.kids[x];
        if (x < B.n) {
            B.order[first + k++] = kk.x;
        } else if (sp + 2 <= 8) {
            st[sp++] = kk.y;
            st[sp++] = kk.x;
        }
    }
}

/* A warp's lanes each take `want` consecutive numbers of *ctr with one
 * atomic: the first of this lane's (every lane calls it). */
__device__ static uint32_t warp_take(uint32_t *ctr, uint32_t want, uint32_t lane)
{
    uint32_t x = want;
    for (int s = 1; s < 32; s <<= 1) {
        const uint32_t y = __shfl_up_sync(FULL, x, s);
        if (lane >= (uint32_t)s)
            x += y;
    }
    const uint32_t total = __shfl_sync(FULL, x, 31);
    uint32_t base = 0;
    if (lane == 31 && total)
        base = atomicAdd(ctr, total);
    return __shfl_sync(FULL, base, 31) + x - want;
}

/* A 4-wide node's slots: binary nodes, their depth-first indices and depths. */
struct Slots {
    uint32_t n[4], dfi[4], depth[4], count;
};

/* Opens inner binary node t.node, then its largest inner child until there
 * are four slots (accel/wide.c's rule), writing each opened binary node. */
__device__ static void open_slots(const Build &B, const Task &t, Slots &s)
{
    const uint2 kk = B.kids[t.node];
    const uint32_t lsub = B.nsub[kk.x];
    put_binary(B, t.dfi, B.box[t.node], t.dfi + 1 + lsub, 0);
    s.n[0] = kk.x, s.dfi[0] = t.dfi + 1, s.depth[0] = t.depth + 1;
    s.n[1] = kk.y, s.dfi[1] = t.dfi + 1 + lsub, s.depth[1] = t.depth + 1;
    s.count = 2;
    while (s.count < 4) {
        int best = -1;
        float ba = -1.0f;
        for (uint32_t j = 0; j < s.count; j++)
            if (!(B.meta[s.n[j]] & COLLAPSED)) {
                const float a = box_area(B.box[s.n[j]]);
                if (a > ba)
                    ba = a, best = (int)j;
            }
        if (best < 0)
            break;
        const uint32_t c = s.n[best], d = s.dfi[best];
        const uint2 ck = B.kids[c];
        const uint32_t cl = B.nsub[ck.x], k = s.count++;
        put_binary(B, d, B.box[c], d + 1 + cl, 0);
        s.n[k] = ck.y, s.dfi[k] = d + 1 + cl, s.depth[k] = s.depth[best] + 1;
        s.n[best] = ck.x, s.dfi[best] = d + 1, s.depth[best] += 1;
    }
}

/* Wide node `wi` from its slots: leaves get their records from `first` on,
 * inner slots the tasks (and 4-wide nodes) from `next` on. */
__device__ static void put_wide(const Build &B, uint32_t wi, const Slots &s, uint32_t first, uint32_t next,
                                uint32_t *maxd, uint32_t *leaves)
{
    RtBvh4Node w;
    for (int j = 0; j < 4; j++) {
        w.lo_x[j] = w.lo_y[j] = w.lo_z[j] = INFINITY;
        w.hi_x[j] = w.hi_y[j] = w.hi_z[j] = -INFINITY;
        w.child[j] = RT_WIDE_EMPTY;
    }
    w.count = s.count;
    w.pad[0] = w.pad[1] = w.pad[2] = 0;
    for (uint32_t j = 0; j < s.count; j++) {
        const uint32_t c = s.n[j], meta = B.meta[c];
        const GBox b = B.box[c];
        w.lo_x[j] = b.lo[0], w.lo_y[j] = b.lo[1], w.lo_z[j] = b.lo[2];
        w.hi_x[j] = b.hi[0], w.hi_y[j] = b.hi[1], w.hi_z[j] = b.hi[2];
        if (meta & COLLAPSED) {
            const uint32_t cnt = meta & ~COLLAPSED;
            gather(B, c, first);
            put_binary(B, s.dfi[j], b, first, cnt);
            w.child[j] = RT_WIDE_LEAF | first << 3 | (cnt - 1u);
            first += cnt;
            *maxd = max(*maxd, s.depth[j]);
            ++*leaves;
        } else {
            B.queue[next] = Task{c, next, s.dfi[j], s.depth[j]};
            w.child[j] = next++;
        }
    }
    B.wide[wi] = w;
}

/* What a slot set takes: records of its leaves, and inner slots. */
__device__ static void slot_needs(const Build &B, const Slots &s, uint32_t *recs, uint32_t *inner)
{
    for (uint32_t j = 0; j < s.count; j++) {
        const uint32_t meta = B.meta[s.n[j]];
        if (meta & COLLAPSED)
            *recs += meta & ~COLLAPSED;
        else
            ++*inner;
    }
}

/* Level `level`'s tasks, queue[mark[level], mark[level + 1]), a warp's 32 at
 * a time, so that the warp takes its records and nodes with one atomic each.
 * A task's 4-wide node has the task's own number (queue and nodes grow together). */
__global__ void k_widen(Build B, int level)
{
    const uint32_t end = B.ctr[C_MARK + level + 1], lane = threadIdx.x & 31u;
    uint32_t maxd = 0, leaves = 0;
    for (uint32_t t0 = B.ctr[C_MARK + level] + blockIdx.x * blockDim.x + (threadIdx.x & ~31u); t0 < end;
         t0 += gridDim.x * blockDim.x) {
        const uint32_t t = t0 + lane;
        const bool on = t < end;
        Slots s;
        s.count = 0;
        uint32_t recs = 0, inner = 0;
        if (on) {
            open_slots(B, B.queue[t], s);
            slot_needs(B, s, &recs, &inner);
        }
        const uint32_t first = warp_take(&B.ctr[C_PRIMS], recs, lane);
        const uint32_t next = warp_take(&B.ctr[C_QTAIL], inner, lane);
        if (on)
            put_wide(B, t, s, first, next, &maxd, &leaves);
    }
    for (int s = 16; s > 0; s >>= 1) {
        maxd = max(maxd, __shfl_xor_sync(FULL, maxd, s));
        leaves += __shfl_xor_sync(FULL, leaves, s);
    }
    if (lane == 0 && leaves) {
        atomicMax(&B.ctr[C_DEPTH], maxd);
        atomicAdd(&B.ctr[C_LEAVES], leaves);
    }
    /* The next level's end, what the queue holds once every block is done:
     * written by the last block to finish (a kernel of its own after each
     * level cost 16 launches, 50 us of 1.5 ms for 891K records). */
    __threadfence();
    __syncthreads();
    if (threadIdx.x == 0 && atomicAdd(&B.ctr[C_WDONE], 1u) == gridDim.x - 1) {
        __threadfence();
        B.ctr[C_MARK + level + 2] = atomicAdd(&B.ctr[C_QTAIL], 0u);
        B.ctr[C_WDONE] = 0;
    }
}

/* The records in leaf order, one thread each: their triangles' and
 * vertices' scattered reads in one wide launch, not in series within each
 * level's tasks (which made the levels half of the build). */
__global__ void k_prims(Build B)
{
    const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < B.n)
        B.prims[i] = record_prim(B, B.rrec[B.order[i]]);
}

/* The collapsed tree's size, and the first task; for a tree that is one
 * leaf, the whole tree: a root with one leaf child (as accel/wide.c makes it). */
__global__ void k_root(Build B)
{
    const uint32_t root = B.ctr[C_ROOT];
    B.ctr[C_NSUB] = B.nsub[root];
    B.ctr[C_QTAIL] = 1;
    if (!(B.meta[root] & COLLAPSED)) {
        B.queue[0] = Task{root, 0, 0, 0};
        B.ctr[C_MARK] = 0;
        B.ctr[C_MARK + 1] = 1;
        return;
    }
    Slots s;
    s.n[0] = root, s.dfi[0] = 0, s.depth[0] = 0, s.count = 1;
    uint32_t maxd = 0, leaves = 0;
    put_wide(B, 0, s, 0, 1, &maxd, &leaves);
    B.ctr[C_PRIMS] = B.meta[root] & ~COLLAPSED;
    B.ctr[C_LEAVES] = 1;
    B.ctr[C_MARK] = B.ctr[C_MARK + 1] = 1; /* (no task) */
}

/* ---------------------------------------------------------------- results */

enum { SAH_BLOCKS = 256 };

/* The SAH cost as accel/sah.c's bvh_sah_cost sums it (area times records,
 * or 1 for an inner node), in fixed partial sums: the same value every run.
 * The last block to finish adds the blocks' sums into part[SAH_BLOCKS]. */
__global__ void k_sah(Build B, double *part)
{
    __shared__ double warp_sum[BLOCK_MAX / 32];
    __shared__ bool last;
    const uint32_t nn = B.ctr[C_NSUB], lane = threadIdx.x & 31u;
    double sum = 0.0;
    for (uint32_t i = blockIdx.x * blockDim.x + threadIdx.x; i < nn; i += gridDim.x * blockDim.x) {
        const RtBvhNode *n = &B.bnodes[i];
        const GBox b = {{n->lo[0], n->lo[1], n->lo[2]}, {n->hi[0], n->hi[1], n->hi[2]}};
        const uint32_t count = n->meta & 0xffu;
        sum += (double)box_area(b) * (count ? (double)count : 1.0);
    }
    for (int s = 16; s > 0; s >>= 1)
        sum += __shfl_xor_sync(FULL, sum, s);
    if (lane == 0)
        warp_sum[threadIdx.x / 32] = sum;
    __syncthreads();
    if (threadIdx.x == 0) {
        double t = 0.0;
        for (uint32_t w = 0; w < blockDim.x / 32; w++)
            t += warp_sum[w];
        part[blockIdx.x] = t;
        __threadfence();
        last = atomicAdd(&B.ctr[C_WDONE], 1u) == gridDim.x - 1;
    }
    __syncthreads();
    if (!last || threadIdx.x >= 32)
        return;
    __threadfence();
    double t = 0.0; /* (lane l adds blocks l, l + 32, ...; then the fixed tree of the warp) */
    for (uint32_t k = lane; k < gridDim.x; k += 32)
        t += ((volatile double *)part)[k];
    for (int s = 16; s > 0; s >>= 1)
        t += __shfl_xor_sync(FULL, t, s);
    if (lane == 0) {
        const RtBvhNode *r = &B.bnodes[0];
        const GBox b = {{r->lo[0], r->lo[1], r->lo[2]}, {r->hi[0], r->hi[1], r->hi[2]}};
        const double root = box_area(b);
        part[SAH_BLOCKS] = root > 0.0 ? t / root : 0.0;
        B.ctr[C_WDONE] = 0;
    }
}

/* schedule.h's slot order, each node in place (no relayout: the same
 * order of slots, so the same visits, as the CPU tree's copy gets). */
__global__ void k_slot_sort(RtBvh4Node *wide, uint32_t n, float x, float y, float z)
{
    const float way[3] = {x, y, z};
    for (uint32_t i = blockIdx.x * blockDim.x + threadIdx.x; i < n; i += gridDim.x * blockDim.x) {
        RtBvh4Node o = wide[i];
        rt_cuda_slot_sort(way, &o);
        wide[i] = o;
    }
}

#endif
