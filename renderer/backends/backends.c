/* backends.c - the table of backends. main.c and the tests pick a backend by
 * name here and never see its internals (dav1d's DSP tables, c-ray's split
 * between library and driver). A backend missing from this build is still
 * listed, with the reason, so that asking for it gives a clear message. */
#include <string.h>

#include "backends.h"
#include "config.h"
#include "rt.h"

extern const RtBackend rt_backend_serial;
#if HAVE_OPENMP
extern const RtBackend rt_backend_openmp;
#endif
#if HAVE_MPI
extern const RtBackend rt_backend_mpi;
#endif
#if HAVE_CUDA
extern const RtBackend rt_backend_cuda;
#endif
#if HAVE_MPI && HAVE_CUDA
extern const RtBackend rt_backend_mpi_cuda;
#endif

#if !HAVE_OPENMP
static const RtBackend openmp_missing = {"openmp", "this build has no OpenMP backend (configure with -Dopenmp=enabled)",
                                         NULL, NULL, NULL, NULL, 0, NULL, 0, 0, NULL, NULL};
#endif
#if !HAVE_MPI
static const RtBackend mpi_missing = {"mpi", "this build has no MPI backend (configure with -Dmpi=enabled)", NULL,
                                      NULL, NULL, NULL, 0, NULL, 0, 0, NULL, NULL};
#endif
#if !HAVE_CUDA
static const RtBackend cuda_missing = {"cuda", "this build has no CUDA backend (configure with -Dcuda=enabled; needs nvcc)",
                                       NULL, NULL, NULL, NULL, 0, NULL, 0, 0, NULL, NULL};
#endif

#if !(HAVE_MPI && HAVE_CUDA)
static const RtBackend mpi_cuda_missing = {"mpi-cuda", "this build has no mpi-cuda backend (it needs both MPI and CUDA)",
                                           NULL, NULL, NULL, NULL, 0, NULL, 0, 0, NULL, NULL};
#endif

static const RtBackend *const backends[] = {
    &rt_backend_serial,
#if HAVE_OPENMP
    &rt_backend_openmp,
#else
    &openmp_missing,
#endif
#if HAVE_MPI
    &rt_backend_mpi,
#else
    &mpi_missing,
#endif
#if HAVE_CUDA
    &rt_backend_cuda,
#else
    &cuda_missing,
#endif
#if HAVE_MPI && HAVE_CUDA
    &rt_backend_mpi_cuda,
#else
    &mpi_cuda_missing,
#endif
    NULL,
};

const RtBackend *const *rt_backend_list(void) { return backends; }

const RtBackend *rt_backend_find(const char *name)
{
    for (int i = 0; backends[i]; i++)
        if (strcmp(backends[i]->name, name) == 0)
            return backends[i];
    return NULL;
}
