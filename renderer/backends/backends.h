/* backends.h - the CPU backends' default tile sizes, which their
 * descriptors (RtBackend.tile, rt.h) carry for the record and --help. */
#ifndef RT_BACKENDS_H
#define RT_BACKENDS_H

#include "rt.h"

/* serial.c's tiles: the oracle's order, which every other backend matches. */
#define RT_SERIAL_TILE 32
/* openmp.c's tiles, handed out by the threaded loop (cpu_tiles.h): the best
 * of the dragon's tile sweep at 2 and at 16 threads (docs/cpu-backends.md,
 * "Scaling"), large enough that the per-tile scheduling cost vanishes, small
 * enough (768 tiles for 512x384) that the last tiles do not leave threads
 * idle. */
#define RT_OMP_TILE 16

#endif
