/* imgdiff.c - compares two images by the measures of RENDERING-RULES:
 * PSNR over the three channels, and over2, the share of pixels whose largest
 * channel difference exceeds 2/255. With thresholds it exits 1 when either is
 * violated, so tests can state them on the command line. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rt.h"

int main(int argc, char **argv)
{
    double min_psnr = -1.0, max_over2 = -1.0;
    const char *a = NULL, *b = NULL;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--min-psnr") == 0 && i + 1 < argc)
            min_psnr = atof(argv[++i]);
        else if (strcmp(argv[i], "--max-over2") == 0 && i + 1 < argc)
            max_over2 = atof(argv[++i]);
        else if (!a)
            a = argv[i];
        else if (!b)
            b = argv[i];
        else {
            fprintf(stderr, "usage: imgdiff A B [--min-psnr DB] [--max-over2 PERCENT]\n");
            return 2;
        }
    }
    if (!a || !b) {
        fprintf(stderr, "usage: imgdiff A B [--min-psnr DB] [--max-over2 PERCENT]\n");
        return 2;
    }
    RtError err;
    uint8_t *pa = NULL, *pb = NULL;
    int wa, ha, wb, hb;
    if (rt_image_read(a, &pa, &wa, &ha, &err) != 0 || rt_image_read(b, &pb, &wb, &hb, &err) != 0) {
        fprintf(stderr, "imgdiff: %s\n", err.msg);
        free(pa);
        return 2;
    }
    if (wa != wb || ha != hb) {
        fprintf(stderr, "imgdiff: sizes differ: %dx%d vs %dx%d\n", wa, ha, wb, hb);
        free(pa);
        free(pb);
        return 1;
    }
    size_t n = (size_t)wa * ha;
    double se = 0.0;
    size_t over2 = 0;
    int maxdiff = 0;
    for (size_t i = 0; i < n; i++) {
        int m = 0;
        for (int c = 0; c < 3; c++) {
            int d = abs((int)pa[3 * i + c] - (int)pb[3 * i + c]);
            se += (double)d * d;
            if (d > m)
                m = d;
        }
        if (m > 2)
            over2++;
        if (m > maxdiff)
            maxdiff = m;
    }
    double mse = se / (3.0 * (double)n);
    double psnr = mse > 0.0 ? 10.0 * log10(255.0 * 255.0 / mse) : INFINITY;
    double pct = 100.0 * (double)over2 / (double)n;
    printf("psnr=%.2f over2=%.4f%% maxdiff=%d pixels=%zu\n", psnr, pct, maxdiff, n);
    free(pa);
    free(pb);
    int bad = (min_psnr >= 0.0 && !(psnr >= min_psnr)) || (max_over2 >= 0.0 && pct > max_over2);
    if (bad)
        fprintf(stderr, "imgdiff: %s vs %s: psnr %.2f dB (min %.2f), over2 %.4f%% (max %.4f%%)\n", a, b, psnr,
                min_psnr, pct, max_over2);
    return bad ? 1 : 0;
}
