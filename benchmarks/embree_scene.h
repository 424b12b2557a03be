/* embree_scene.h - a raybench scene's triangles as an Embree 3 triangle
 * geometry, committed, with the high-quality build (spatial splits): the one
 * copy the benchmark drivers (embree_build.c, embree_render.c) share. NULL
 * when Embree cannot allocate its buffers. */
#ifndef RT_EMBREE_SCENE_H
#define RT_EMBREE_SCENE_H

#include <embree3/rtcore.h>

#include "rt.h"

static inline RTCGeometry embree_triangles(RTCDevice dev, const RtScene *sc)
{
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    float *v = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                       sc->nvertices ? sc->nvertices : 1);
    unsigned *ix = rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
                                           sc->ntriangles);
    if (!v || !ix) {
        rtcReleaseGeometry(g);
        return NULL;
    }
    for (uint32_t i = 0; i < sc->nvertices; i++) {
        v[3 * i] = sc->vertices[i].x;
        v[3 * i + 1] = sc->vertices[i].y;
        v[3 * i + 2] = sc->vertices[i].z;
    }
    for (uint32_t i = 0; i < sc->ntriangles; i++)
        for (int k = 0; k < 3; k++)
            ix[3 * i + k] = (unsigned)sc->triangles[i].v[k];
    rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_HIGH);
    rtcCommitGeometry(g);
    return g;
}

#endif
