/* rt_camera.h - primary rays (RENDERING-RULES "Camera"). */
#ifndef RT_CAMERA_H
#define RT_CAMERA_H

#include "rt_scene.h"

typedef struct RtRay {
    RtVec3 o; /* origin */
    RtVec3 d; /* direction, unit length */
} RtRay;

/* Pixel column i from the left, row j from the top. The film plane sits at
 * distance d along -fwd; +right is towards column 0. */
static inline RT_HD RtRay rt_camera_ray(const RtCamera *cam, int i, int j)
{
    float sx = 0.5f * (float)cam->width - ((float)i + 0.5f);
    float sy = 0.5f * (float)cam->height - ((float)j + 0.5f);
    RtVec3 dir = rt_scale(cam->fwd, -cam->d);
    dir = rt_madd(dir, cam->right, sx);
    dir = rt_madd(dir, cam->up, sy);
    RtRay r;
    r.o = cam->pos;
    r.d = rt_normalize(dir);
    return r;
}

#endif
