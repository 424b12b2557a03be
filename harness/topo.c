/* topo.c: machine topology (hwloc) and the placement of each run's workers.
 *
 * GPU backends: worker (rank) w drives GPU w mod G (mpi-cuda's device rule
 * under CUDA_DEVICE_ORDER=PCI_BUS_ID), so it is placed on a free core of
 * that GPU's NUMA node (hwloc's PCI locality), as close as the machine
 * allows to the GPU's PCIe root.
 *
 * Policies: `close` fills physical cores in hwloc's logical order; `spread`
 * takes cores round-robin across packages (the same order as Open MPI's
 * `--map-by socket`), so two threads on a two-socket machine land on two
 * sockets; on one package it equals `close`. `none` leaves placement to the
 * OS. One worker per physical core: SMT siblings share execution units, so
 * putting two threads on one core would measure the core, not the scaling.
 * After a run, hx_pin_held checks the plan against the cores the renderer
 * reports; a run that srun spreads over a job's nodes is planned and
 * checked node by node ("0,1|0,1"). */
#define _GNU_SOURCE 1 /* sched_getaffinity, CPU_SET */
#include "hx.h"

#include "config.h"

#include <sched.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#if HAVE_HWLOC
#include <hwloc.h>
#endif

#if HAVE_HWLOC
/* NVIDIA GPUs (PCI vendor 0x10de, class display/3D) in bus order, each with
 * the cores of its nearest non-I/O ancestor (its NUMA node or package). */
static void topo_gpus(HxTopo *t)
{
    hwloc_topology_t topo = (hwloc_topology_t)t->topo;
    hwloc_obj_type_t ct = hwloc_get_nbobjs_by_type(topo, HWLOC_OBJ_CORE) > 0 ? HWLOC_OBJ_CORE : HWLOC_OBJ_PU;
    for (hwloc_obj_t d = hwloc_get_next_pcidev(topo, NULL); d; d = hwloc_get_next_pcidev(topo, d)) {
        const struct hwloc_pcidev_attr_s *a = &d->attr->pcidev;
        if (a->vendor_id != 0x10de || (a->class_id >> 8) != 0x03)
            continue;
        hwloc_obj_t near = hwloc_get_non_io_ancestor_obj(topo, d);
        int g = t->ngpus++;
        t->gpu_bus = hx_xrealloc(t->gpu_bus, (size_t)t->ngpus * sizeof *t->gpu_bus);
        t->gpu_cores = hx_xrealloc(t->gpu_cores, (size_t)t->ngpus * sizeof *t->gpu_cores);
        t->gpu_ncores = hx_xrealloc(t->gpu_ncores, (size_t)t->ngpus * sizeof *t->gpu_ncores);
        HxBuf b = {0};
        hx_buf_printf(&b, "%04x:%02x:%02x.%x", a->domain, a->bus, a->dev, a->func);
        t->gpu_bus[g] = b.s;
        t->gpu_cores[g] = hx_xmalloc((size_t)t->ncores * sizeof(int));
        t->gpu_ncores[g] = 0;
        for (int i = 0; i < t->ncores; i++) {
            hwloc_obj_t c = hwloc_get_obj_by_type(topo, ct, (unsigned)i);
            if (c && near && hwloc_bitmap_intersects(c->cpuset, near->cpuset))
                t->gpu_cores[g][t->gpu_ncores[g]++] = i;
        }
    }
    /* bus order (hwloc's walk follows the PCI tree, not the bus numbers) */
    for (int i = 1; i < t->ngpus; i++)
        for (int j = i; j > 0 && strcmp(t->gpu_bus[j], t->gpu_bus[j - 1]) < 0; j--) {
            char *s = t->gpu_bus[j]; t->gpu_bus[j] = t->gpu_bus[j - 1]; t->gpu_bus[j - 1] = s;
            int *c = t->gpu_cores[j]; t->gpu_cores[j] = t->gpu_cores[j - 1]; t->gpu_cores[j - 1] = c;
            int n = t->gpu_ncores[j]; t->gpu_ncores[j] = t->gpu_ncores[j - 1]; t->gpu_ncores[j - 1] = n;
        }
}
#endif

int hx_topo_load(HxTopo *t)
{
    memset(t, 0, sizeof *t);
#if HAVE_HWLOC
    hwloc_topology_t topo;
    if (hwloc_topology_init(&topo) == 0 &&
        hwloc_topology_set_io_types_filter(topo, HWLOC_TYPE_FILTER_KEEP_IMPORTANT) == 0 &&
        hwloc_topology_load(topo) == 0) {
        /* Only the CPUs this process may use (taskset, a Slurm allocation,
         * a cgroup): every count and every planned core comes from them. */
        hwloc_bitmap_t allowed = hwloc_bitmap_alloc();
        if (allowed && hwloc_get_cpubind(topo, allowed, HWLOC_CPUBIND_PROCESS) == 0 &&
            !hwloc_bitmap_iszero(allowed) &&
            !hwloc_bitmap_isincluded(hwloc_topology_get_topology_cpuset(topo), allowed))
            t->restricted = hwloc_topology_restrict(topo, allowed, HWLOC_RESTRICT_FLAG_ADAPT_IO) == 0;
        hwloc_bitmap_free(allowed);
        t->topo = topo;
        t->have_hwloc = 1;
        t->ncores = hwloc_get_nbobjs_by_type(topo, HWLOC_OBJ_CORE);
        t->npus = hwloc_get_nbobjs_by_type(topo, HWLOC_OBJ_PU);
        t->npackages = hwloc_get_nbobjs_by_type(topo, HWLOC_OBJ_PACKAGE);
        t->numa_nodes = hwloc_get_nbobjs_by_type(topo, HWLOC_OBJ_NUMANODE);
        if (t->ncores <= 0)
            t->ncores = t->npus; /* some VMs report PUs only */
        if (t->npackages <= 0)
            t->npackages = 1;
        t->core_os = hx_xmalloc((size_t)t->ncores * sizeof(int));
        t->core_pus = hx_xmalloc((size_t)t->ncores * sizeof(char *));
        int *pkg = t->core_pkg = hx_xmalloc((size_t)t->ncores * sizeof(int));
        t->core_in_pkg = hx_xmalloc((size_t)t->ncores * sizeof(int));
        hwloc_obj_type_t ct = hwloc_get_nbobjs_by_type(topo, HWLOC_OBJ_CORE) > 0
                                  ? HWLOC_OBJ_CORE : HWLOC_OBJ_PU;
        for (int i = 0; i < t->ncores; i++) {
            hwloc_obj_t c = hwloc_get_obj_by_type(topo, ct, (unsigned)i);
            HxBuf b = {0};
            int first = -1;
            unsigned id;
            hwloc_bitmap_foreach_begin(id, c->cpuset) {
                if (first < 0)
                    first = (int)id;
                hx_buf_printf(&b, "%s%u", b.len ? "," : "", id);
            } hwloc_bitmap_foreach_end();
            t->core_os[i] = first;
            t->core_pus[i] = b.s ? b.s : hx_strdup("?");
            hwloc_obj_t p = hwloc_get_ancestor_obj_by_type(topo, HWLOC_OBJ_PACKAGE, c);
            pkg[i] = p ? (int)p->logical_index : 0;
            t->core_in_pkg[i] = 0;
            for (int k = 0; k < i; k++)
                t->core_in_pkg[i] += pkg[k] == pkg[i];
        }
        /* spread order: i-th core of each package in turn */
        t->spread_order = hx_xmalloc((size_t)t->ncores * sizeof(int));
        int k = 0;
        for (int round = 0; k < t->ncores; round++) {
            for (int p = 0; p < t->npackages; p++) {
                int seen = 0;
                for (int i = 0; i < t->ncores; i++) {
                    if (pkg[i] != p)
                        continue;
                    if (seen++ == round) {
                        t->spread_order[k++] = i;
                        break;
                    }
                }
            }
            if (round > t->ncores)
                break;
        }
        topo_gpus(t);
        return 0;
    }
#endif
    /* Without hwloc: the CPUs this process may use, planned but not bound. */
    cpu_set_t set;
    int ids[CPU_SETSIZE], n = 0;
    if (sched_getaffinity(0, sizeof set, &set) == 0)
        for (int c = 0; c < CPU_SETSIZE; c++)
            if (CPU_ISSET(c, &set))
                ids[n++] = c;
    if (n == 0) {
        long on = sysconf(_SC_NPROCESSORS_ONLN);
        for (n = 0; n < (on > 0 ? on : 1) && n < CPU_SETSIZE; n++)
            ids[n] = n;
    }
    t->ncores = t->npus = n;
    t->npackages = 1;
    t->core_os = hx_xmalloc((size_t)t->ncores * sizeof(int));
    t->core_pus = hx_xmalloc((size_t)t->ncores * sizeof(char *));
    t->spread_order = hx_xmalloc((size_t)t->ncores * sizeof(int));
    t->core_pkg = hx_xmalloc((size_t)t->ncores * sizeof(int));
    t->core_in_pkg = hx_xmalloc((size_t)t->ncores * sizeof(int));
    for (int i = 0; i < t->ncores; i++) {
        char b[16];
        t->core_pkg[i] = 0;
        t->core_in_pkg[i] = i;
        snprintf(b, sizeof b, "%d", ids[i]);
        t->core_os[i] = ids[i];
        t->core_pus[i] = hx_strdup(b);
        t->spread_order[i] = i;
    }
    return 0;
}

void hx_topo_free(HxTopo *t)
{
#if HAVE_HWLOC
    if (t->topo)
        hwloc_topology_destroy((hwloc_topology_t)t->topo);
#endif
    for (int i = 0; i < t->ncores; i++)
        free(t->core_pus[i]);
    free(t->core_pus);
    free(t->core_os);
    free(t->spread_order);
    free(t->core_pkg);
    free(t->core_in_pkg);
    for (int g = 0; g < t->ngpus; g++) {
        free(t->gpu_bus[g]);
        free(t->gpu_cores[g]);
    }
    free(t->gpu_bus);
    free(t->gpu_cores);
    free(t->gpu_ncores);
    memset(t, 0, sizeof *t);
}

int hx_slurm_nodes(void)
{
    const char *s = getenv("SLURM_JOB_NUM_NODES");
    long n;
    return s && hx_parse_int(s, 1, 1000000, &n) == 0 ? (int)n : 1;
}

/* Worker w of a GPU run (cores[0..w) placed): the first free core near GPU
 * w mod G, else the first free core, else (oversubscribed) core w mod N. */
static int gpu_core(const HxTopo *t, int w, const int *cores)
{
    const int g = w % t->ngpus;
    for (int pass = 0; pass < 2; pass++) {
        const int n = pass == 0 ? t->gpu_ncores[g] : t->ncores;
        for (int k = 0; k < n; k++) {
            const int c = pass == 0 ? t->gpu_cores[g][k] : k;
            int used = 0;
            for (int v = 0; v < w; v++)
                used |= cores[v] == c;
            if (!used)
                return c;
        }
    }
    return w % t->ncores;
}

char *hx_rankfile(const HxTopo *t, const HxRun *r)
{
    if (r->ncores == 0)
        return NULL;
    HxBuf b = {0};
    for (int w = 0; w < r->ncores; w++)
        hx_buf_printf(&b, "rank %d=localhost slot=%d:%d\n", w, t->core_pkg[r->cores[w]],
                      t->core_in_pkg[r->cores[w]]);
    return b.s;
}

/* The cores of each node's ranks when srun spreads P ranks of T threads
 * over n nodes, nodes separated by '|' ("0,1|0,1"). srun's block
 * distribution deals the ranks out evenly (the first P mod n nodes get one
 * more) and numbers them node by node; on each node --cpu-bind=cores gives
 * them consecutive cores, as on one node. The nodes are taken to be alike:
 * the harness sees only its own. */
static char *plan_per_node(const HxTopo *t, long P, long T, int n, int spread)
{
    HxBuf b = {0};
    for (int k = 0; k < n; k++) {
        long on = (P / n + (k < P % n)) * T;
        hx_buf_put(&b, k ? "|" : "");
        for (long w = 0; w < on; w++) {
            int c = (int)(w % t->ncores); /* oversubscribed: wrap around */
            hx_buf_printf(&b, "%s%d", w ? "," : "", t->core_os[spread ? t->spread_order[c] : c]);
        }
    }
    return b.s;
}

void hx_plan_cores(const HxTopo *t, const HxConfig *cfg, HxPlan *plan)
{
    int nodes = cfg->launcher == HX_LAUNCHER_SRUN ? hx_slurm_nodes() : 1;
    for (size_t i = 0; i < plan->n; i++) {
        HxRun *r = &plan->runs[i];
        free(r->cores);
        free(r->cores_planned);
        r->cores = NULL;
        r->ncores = 0;
        /* srun spreads an MPI run's ranks over the job's nodes (over as
         * many nodes as it has ranks, when it has fewer) */
        long P = 1, T = 1;
        if (hx_run_is_mpi(r->v) && strcmp(r->v[HX_DIM_RANKS], "-") != 0)
            hx_parse_int(r->v[HX_DIM_RANKS], 1, 4096, &P);
        if (strcmp(r->v[HX_DIM_THREADS], "-") != 0)
            hx_parse_int(r->v[HX_DIM_THREADS], 1, 4096, &T);
        int span = P < nodes ? (int)P : nodes;
        /* the fullest node's workers against the cores of one node */
        long busiest = span > 1 ? (P + span - 1) / span * T : r->workers;
        r->oversubscribed = busiest > t->ncores;
        r->refused = r->oversubscribed && !cfg->oversubscribe_allow;
        int spread = strcmp(r->v[HX_DIM_PIN], "spread") == 0;
        int gpu = hx_backend_gpu(r->v[HX_DIM_BACKEND]) && t->ngpus > 0;
        if (strcmp(r->v[HX_DIM_PIN], "none") == 0 || r->refused) {
            r->cores_planned = hx_strdup("-");
            continue;
        }
        if (span > 1) {
            /* Planned per node; srun binds, the harness binds nothing. A
             * command study's CPUs are watched on this node only, and GPU
             * placement is per node too: no plan for those. */
            r->cores_planned = gpu || cfg->prog ? hx_strdup("-") : plan_per_node(t, P, T, span, spread);
            continue;
        }
        r->ncores = r->workers;
        r->cores = hx_xmalloc((size_t)r->workers * sizeof(int));
        HxBuf b = {0};
        for (int w = 0; w < r->workers; w++) {
            /* oversubscribed: wrap around, two workers per core */
            int k = w % t->ncores;
            int c = gpu ? gpu_core(t, w, r->cores) : spread ? t->spread_order[k] : k;
            r->cores[w] = c;
            hx_buf_printf(&b, "%s%d", w ? "," : "", t->core_os[c]);
        }
        r->cores_planned = b.s;
    }
}

int hx_bind_child(const HxTopo *t, const HxRun *r)
{
#if HAVE_HWLOC
    if (!t->have_hwloc || r->ncores == 0)
        return 0;
    hwloc_topology_t topo = (hwloc_topology_t)t->topo;
    hwloc_bitmap_t set = hwloc_bitmap_alloc();
    hwloc_obj_type_t ct = hwloc_get_nbobjs_by_type(topo, HWLOC_OBJ_CORE) > 0
                              ? HWLOC_OBJ_CORE : HWLOC_OBJ_PU;
    for (int w = 0; w < r->ncores; w++) {
        hwloc_obj_t c = hwloc_get_obj_by_type(topo, ct, (unsigned)r->cores[w]);
        if (c)
            hwloc_bitmap_or(set, set, c->cpuset);
    }
    /* The whole process (and what it execs) is bound; OpenMP then places its
     * threads on the places we give it inside this set. */
    int rc = hwloc_set_cpubind(topo, set, HWLOC_CPUBIND_PROCESS);
    hwloc_bitmap_free(set);
    return rc;
#else
    (void)t;
    (void)r;
    return 0;
#endif
}

char *hx_omp_places(const HxTopo *t, const HxRun *r)
{
    /* One place per planned core listing all its PUs; duplicates (when
     * oversubscribed) are listed once. */
    HxBuf b = {0};
    for (int w = 0; w < r->ncores; w++) {
        int dup = 0;
        for (int k = 0; k < w; k++)
            dup |= r->cores[k] == r->cores[w];
        if (dup)
            continue;
        hx_buf_printf(&b, "%s{%s}", b.len ? "," : "", t->core_pus[r->cores[w]]);
    }
    return b.s ? b.s : hx_strdup("cores");
}

void hx_topo_print(const HxTopo *t, FILE *out)
{
    fprintf(out, "topology (%s): %d package(s), %d NUMA node(s), %d physical core(s), %d PU(s), SMT %s\n",
            t->have_hwloc ? "hwloc" : "no hwloc: sysconf, no pinning",
            t->npackages, t->numa_nodes, t->ncores, t->npus,
            t->npus > t->ncores ? "on" : "off");
#if HAVE_HWLOC
    if (t->have_hwloc) {
        hwloc_topology_t topo = (hwloc_topology_t)t->topo;
        for (int d = 0; d < hwloc_topology_get_depth(topo); d++) {
            hwloc_obj_t o = hwloc_get_obj_by_depth(topo, (unsigned)d, 0);
            if (!o)
                continue;
            char type[64];
            hwloc_obj_type_snprintf(type, sizeof type, o, 0);
            int n = hwloc_get_nbobjs_by_depth(topo, (unsigned)d);
            if (o->attr && hwloc_obj_type_is_cache(o->type))
                fprintf(out, "  depth %d: %d x %s (%llu KiB)\n", d, n, type,
                        (unsigned long long)(o->attr->cache.size / 1024));
            else
                fprintf(out, "  depth %d: %d x %s\n", d, n, type);
        }
    }
#endif
    fprintf(out, "cores (logical index: OS PUs):");
    for (int i = 0; i < t->ncores; i++)
        fprintf(out, " %d:{%s}", i, t->core_pus[i]);
    fprintf(out, "\nspread order:");
    for (int i = 0; i < t->ncores; i++)
        fprintf(out, " %d", t->spread_order[i]);
    fputc('\n', out);
    for (int g = 0; g < t->ngpus; g++) {
        fprintf(out, "GPU %d (PCI %s), nearest cores:", g, t->gpu_bus[g]);
        for (int k = 0; k < t->gpu_ncores[g]; k++)
            fprintf(out, " %d", t->gpu_cores[g][k]);
        fputc('\n', out);
    }
}

/* ---- `harness topo [CONFIG]` ---- */
#include <getopt.h>

static void usage_topo(FILE *f)
{
    fputs("usage: harness topo [CONFIG]\n"
          "Prints the hwloc topology summary and, with CONFIG, the cores each planned\n"
          "run would be bound to (policy close/spread/none, oversubscription).\n"
          "  -h, --help   this text\n", f);
}

int hx_cmd_topo(int argc, char **argv)
{
    static const struct option lo[] = {{"help", no_argument, NULL, 'h'}, {NULL, 0, NULL, 0}};
    int c;
    while ((c = getopt_long(argc, argv, "h", lo, NULL)) != -1) {
        if (c == 'h') {
            usage_topo(stdout);
            return 0;
        }
        usage_topo(stderr);
        return 1;
    }
    if (argc - optind > 1) {
        fprintf(stderr, "harness topo: at most one CONFIG argument (see --help)\n");
        return 1;
    }
    HxTopo t;
    hx_topo_load(&t);
    hx_topo_print(&t, stdout);
    int rc = 0;
    if (optind < argc) {
        HxConfig cfg;
        if (hx_config_open(argv[optind], &cfg)) {
            rc = 1;
        } else {
            HxPlan plan;
            hx_expand(&cfg, &plan);
            hx_plan_cores(&t, &cfg, &plan);
            printf("planned cores for %s (%zu runs):\n", cfg.path, plan.n);
            for (size_t i = 0; i < plan.n; i++) {
                const HxRun *r = &plan.runs[i];
                if (r->warmup)
                    continue;
                printf("  %-4zu %s  workers=%d cores=%s%s%s\n", i + 1, r->run_id, r->workers,
                       r->cores_planned, r->oversubscribed ? " oversubscribed" : "",
                       r->refused ? " REFUSED" : "");
            }
            hx_plan_free(&plan);
        }
        hx_config_free(&cfg);
    }
    hx_topo_free(&t);
    return rc;
}

/* ---- pinning check (harness run) ---- */

static int parse_int_set(const char *s, int *out, int max)
{
    int n = 0;
    const char *p = s;
    while (*p && n < max) {
        char *end;
        long v = strtol(p, &end, 10);
        if (end == p)
            return -1;
        out[n++] = (int)v;
        p = end;
        if (*p == ',')
            p++;
        else if (*p)
            return -1;
    }
    return n;
}

static int count_distinct(const int *v, int n)
{
    int d = 0;
    for (int i = 0; i < n; i++) {
        int seen = 0;
        for (int k = 0; k < i; k++)
            seen |= v[k] == v[i];
        d += !seen;
    }
    return d;
}

/* One node's cores against its plan (lists of length pl and al): 0 yes,
 * 1 partial, 2 no, -1 unknown (nothing reported, or not a list). */
static int held_node(const char *planned, size_t pl, const char *actual, size_t al)
{
    char *ps = hx_strndup(planned, pl), *as = hx_strndup(actual, al);
    int p[4096], a[4096];
    int np = parse_int_set(ps, p, 4096), na = parse_int_set(as, a, 4096);
    free(ps);
    free(as);
    if (np <= 0 || na <= 0)
        return -1;
    for (int i = 0; i < na; i++) {
        int in = 0;
        for (int k = 0; k < np; k++)
            in |= a[i] == p[k];
        if (!in)
            return 2;
    }
    return count_distinct(a, na) == count_distinct(p, np) ? 0 : 1;
}

/* yes: every reported core is planned and as many distinct cores were used
 * as planned; partial: planned cores only, but fewer of them (threads shared
 * a core); no: a thread ran outside the plan. A plan of several nodes
 * ("0,1|0,1") is checked node by node against cores reported per node:
 * core 0 of one node is not core 0 of another. */
const char *hx_pin_held(const char *planned, const char *actual)
{
    static const char *const word[] = {"yes", "partial", "no"};
    if (!planned || strcmp(planned, "-") == 0)
        return "n/a";
    if (!actual || !*actual)
        return "unknown";
    int worst = 0;
    for (const char *p = planned, *a = actual;; ) {
        size_t pl = strcspn(p, "|"), al = strcspn(a, "|");
        int v = held_node(p, pl, a, al);
        if (v < 0)
            return "unknown";
        worst = v > worst ? v : worst;
        if (!p[pl] || !a[al])
            return p[pl] || a[al] ? "no" : word[worst]; /* ranks on other nodes than planned */
        p += pl + 1;
        a += al + 1;
    }
}

static int cmp_int(const void *x, const void *y)
{
    return (*(const int *)x > *(const int *)y) - (*(const int *)x < *(const int *)y);
}

char *hx_cores_by_node(const char *rank_node, const char *rank_cores)
{
    if (!rank_node || !rank_cores || !*rank_node)
        return NULL;
    enum { MAX = 4096 };
    int node[MAX], nranks = 0, nnodes = 0;
    for (const char *p = rank_node; nranks < MAX; p++) {
        char *end;
        long v = strtol(p, &end, 10);
        if (end == p || v < 0 || v >= MAX || (*end && *end != '/'))
            return NULL;
        node[nranks++] = (int)v;
        nnodes = (int)v + 1 > nnodes ? (int)v + 1 : nnodes;
        if (!*(p = end))
            break;
    }
    HxBuf b = {0};
    int *cores = hx_xmalloc(MAX * sizeof(int));
    int ok = 1;
    for (int k = 0; k < nnodes && ok; k++) {
        int nc = 0, r = 0;
        /* the cores of rank r are rank_cores' r-th '/'-separated field */
        for (const char *f = rank_cores; ok; r++) {
            size_t len = strcspn(f, "/");
            if (r >= nranks) {
                ok = 0;
                break;
            }
            for (const char *c = f; node[r] == k && c < f + len && nc < MAX;) {
                char *end;
                long v = strtol(c, &end, 10);
                if (end == c || end > f + len) {
                    ok = 0;
                    break;
                }
                cores[nc++] = (int)v;
                c = *end == ',' ? end + 1 : end;
            }
            if (!f[len])
                break;
            f += len + 1;
        }
        ok &= r == nranks - 1;
        qsort(cores, (size_t)nc, sizeof *cores, cmp_int);
        hx_buf_put(&b, k ? "|" : "");
        for (int i = 0; i < nc; i++)
            if (i == 0 || cores[i] != cores[i - 1])
                hx_buf_printf(&b, "%s%d", i ? "," : "", cores[i]);
    }
    free(cores);
    if (!ok) {
        hx_buf_free(&b);
        return NULL;
    }
    return b.s ? b.s : hx_strdup("");
}

const char *hx_pin_held_row(const char *planned, char **vals)
{
    int ka = hx_column_index("cores_actual"), ke = hx_column_index("extra");
    if (!planned || !strchr(planned, '|'))
        return hx_pin_held(planned, vals[ka]);
    /* raytrace's cores= is the union over every node's CPU numbers: the
     * cores per node come from its rank_node and rank_cores instead */
    char nodes[8192], cores[16384];
    const char *ex = vals[ke] ? vals[ke] : "";
    char *per = hx_kv_get(ex, "rank_node", nodes, sizeof nodes) && hx_kv_get(ex, "rank_cores", cores, sizeof cores)
                    ? hx_cores_by_node(nodes, cores) : NULL;
    if (!per)
        return "unknown";
    hx_row_set(vals, "cores_actual", per);
    free(per);
    return hx_pin_held(planned, vals[ka]);
}
