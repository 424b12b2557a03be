/* openmp.c - placeholder until the OpenMP backend lands. */
#include "rt.h"
const RtBackend rt_backend_openmp = {"openmp", "the OpenMP backend is not implemented yet", NULL, NULL, NULL};
