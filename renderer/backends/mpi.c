/* mpi.c - placeholder until the MPI backend lands. */
#include "rt.h"
const RtBackend rt_backend_mpi = {"mpi", "the MPI backend is not implemented yet", NULL, NULL, NULL};
