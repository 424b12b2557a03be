/* alloc_program.c - a program of known peak memory for the harness's
 * measurement (test-memory.sh): `alloc_program MIB` (a command study), or
 * with the harness's raytrace arguments the MiB its scene's base name says
 * (alloc256.txt: 256 MiB). It writes every page so that all of it is
 * resident, and prints a record line as raytrace does. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int main(int argc, char **argv)
{
    const char *scene = argc > 1 ? argv[argc - 1] : "";
    const char *base = strrchr(scene, '/') ? strrchr(scene, '/') + 1 : scene;
    const int number = *base && strspn(base, "0123456789") == strlen(base);
    const long mib = number ? atol(base) : strncmp(base, "alloc", 5) == 0 ? atol(base + 5) : 0;
    const size_t n = (size_t)mib << 20;
    volatile char *p = n ? malloc(n) : NULL;
    if (n && !p)
        return 1;
    for (size_t i = 0; i < n; i += 4096)
        p[i] = (char)i;
    printf("record: scene=alloc%ld width=1 height=1 backend=serial accel=bvh threads=1 ranks=1 render_ms=1.0 "
           "total_ms=1.0 image_fnv1a=00000000000000aa cores=0\n", mib);
    free((void *)p);
    return 0;
}
