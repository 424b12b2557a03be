/* backends.h - what the table of backends (backends.c) says about a backend
 * beyond its descriptor (rt.h): the tile size it renders without --tile. */
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

/* The side of the square tiles `be` renders when --tile is not given, as the
 * record's tile= shows it. */
int rt_backend_tile(const RtBackend *be);

#endif
