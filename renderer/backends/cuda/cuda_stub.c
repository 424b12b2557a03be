/* cuda_stub.c - placeholder until the CUDA backend lands. */
#include "rt.h"
const RtBackend rt_backend_cuda = {"cuda", "the CUDA backend is not implemented yet", NULL, NULL, NULL};
