/* image.c - PNG (libpng), BMP and PPM, chosen by the file name's extension.
 * Writes go through io/atomic.c: an image appears whole or not at all. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <setjmp.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#include "config.h"
#include "rt.h"
#if HAVE_PNG
#include <png.h>
#include <zlib.h>
#endif

RtImageFormat rt_image_format_for(const char *path)
{
    const char *dot = strrchr(path, '.');
    const char *slash = strrchr(path, '/');
    if (!dot || (slash && dot < slash))
        return RT_IMG_UNKNOWN;
    if (strcasecmp(dot, ".png") == 0)
        return RT_IMG_PNG;
    if (strcasecmp(dot, ".bmp") == 0)
        return RT_IMG_BMP;
    if (strcasecmp(dot, ".ppm") == 0)
        return RT_IMG_PPM;
    return RT_IMG_UNKNOWN;
}

#if HAVE_PNG
typedef struct PngErr {
    jmp_buf jb;
    char msg[256];
} PngErr;

static void png_error_cb(png_structp png, png_const_charp msg)
{
    PngErr *pe = (PngErr *)png_get_error_ptr(png);
    snprintf(pe->msg, sizeof pe->msg, "%s", msg);
    longjmp(pe->jb, 1);
}
static void png_warn_cb(png_structp png, png_const_charp msg)
{
    (void)png;
    (void)msg;
}

/* PNG written through zlib on every core, as pigz compresses (Mark Adler,
 * pigz.c): the Up-filtered rows cut into pieces of about PNG_PIECE bytes,
 * each deflated on a thread of its own with the 32 KiB before it as its
 * dictionary and ended on a byte boundary (Z_SYNC_FLUSH), the pieces'
 * Adler-32 checksums combined: one zlib stream in consecutive IDAT chunks,
 * which every PNG reader reads. The pieces are cut by rows, not by threads,
 * so the bytes are the same on any number of cores. Level 3: most of level
 * 9's size for a fraction of its time; one filter (Up) instead of a choice
 * per row: half the time, files within a few percent (docs/performance.md). */
enum { PNG_PIECE = 256 * 1024, PNG_DICT = 32768, PNG_LEVEL = 3 };

typedef struct PngPiece {
    unsigned char *out;
    size_t len, raw;
    uLong adler;
    int ok;
} PngPiece;

/* Row y, Up-filtered, into dst (1 + 3w bytes). */
static void png_filter_row(const uint8_t *rgb, int w, int y, unsigned char *dst)
{
    const size_t n = (size_t)w * 3;
    const uint8_t *cur = rgb + (size_t)y * n, *prev = cur - n;
    dst[0] = 2;
    for (size_t i = 0; i < n; i++)
        dst[1 + i] = (unsigned char)(cur[i] - (y ? prev[i] : 0));
}

/* Rows [y0, y1) filtered and deflated into p (p->ok 0: out of memory). */
static void png_piece(const uint8_t *rgb, int w, int y0, int y1, int last, PngPiece *p)
{
    const size_t rowb = 1 + (size_t)w * 3;
    const int before = (int)((PNG_DICT + rowb - 1) / rowb), d0 = y0 > before ? y0 - before : 0;
    const size_t nd = (size_t)(y0 - d0) * rowb, nr = (size_t)(y1 - y0) * rowb, dict = nd < PNG_DICT ? nd : PNG_DICT;
    unsigned char *in = malloc(nd + nr);
    z_stream z;
    memset(p, 0, sizeof *p);
    memset(&z, 0, sizeof z);
    if (!in || deflateInit2(&z, PNG_LEVEL, Z_DEFLATED, -15, 8, Z_DEFAULT_STRATEGY) != Z_OK) {
        free(in);
        return;
    }
    for (int y = d0; y < y1; y++)
        png_filter_row(rgb, w, y, in + (size_t)(y - d0) * rowb);
    const size_t cap = deflateBound(&z, (uLong)nr) + 64;
    if ((!dict || deflateSetDictionary(&z, in + nd - dict, (uInt)dict) == Z_OK) && (p->out = malloc(cap))) {
        z.next_in = in + nd;
        z.avail_in = (uInt)nr;
        z.next_out = p->out;
        z.avail_out = (uInt)cap;
        const int rc = deflate(&z, last ? Z_FINISH : Z_SYNC_FLUSH);
        p->ok = (last ? rc == Z_STREAM_END : rc == Z_OK) && z.avail_in == 0;
        p->len = cap - z.avail_out;
        p->raw = nr;
        p->adler = adler32(1L, in + nd, (uInt)nr);
    }
    deflateEnd(&z);
    free(in);
}

/* One chunk: its length, type, data and CRC. */
static int png_chunk(FILE *fp, const char *type, const unsigned char *data, size_t len)
{
    unsigned char head[8] = {(unsigned char)(len >> 24), (unsigned char)(len >> 16), (unsigned char)(len >> 8),
                             (unsigned char)len, (unsigned char)type[0], (unsigned char)type[1],
                             (unsigned char)type[2], (unsigned char)type[3]};
    uLong crc = crc32(crc32(0L, Z_NULL, 0), head + 4, 4);
    if (len)
        crc = crc32(crc, data, (uInt)len);
    const unsigned char tail[4] = {(unsigned char)(crc >> 24), (unsigned char)(crc >> 16), (unsigned char)(crc >> 8),
                                   (unsigned char)crc};
    return fwrite(head, 1, 8, fp) == 8 && (!len || fwrite(data, 1, len, fp) == len) && fwrite(tail, 1, 4, fp) == 4
               ? 0 : -1;
}

static int write_png(FILE *fp, const uint8_t *rgb, int w, int h, char *msg, size_t msz)
{
    static const unsigned char sig[8] = {137, 80, 78, 71, 13, 10, 26, 10}, zhead[2] = {0x78, 0x5e};
    const unsigned char ihdr[13] = {(unsigned char)(w >> 24), (unsigned char)(w >> 16), (unsigned char)(w >> 8),
                                    (unsigned char)w, (unsigned char)(h >> 24), (unsigned char)(h >> 16),
                                    (unsigned char)(h >> 8), (unsigned char)h, 8, 2, 0, 0, 0};
    const size_t rowb = 1 + (size_t)w * 3;
    const int rows = rowb >= PNG_PIECE ? 1 : (int)(PNG_PIECE / rowb), npieces = (h + rows - 1) / rows;
    const int batch = 4 * rt_thread_count(0);
    PngPiece *pc = calloc((size_t)batch, sizeof *pc);
    uLong adler = adler32(0L, Z_NULL, 0);
    int rc = pc && fwrite(sig, 1, 8, fp) == 8 && png_chunk(fp, "IHDR", ihdr, 13) == 0 &&
                     png_chunk(fp, "IDAT", zhead, 2) == 0 ? 0 : -1;
    for (int b0 = 0; rc == 0 && b0 < npieces; b0 += batch) {
        const int nb = npieces - b0 < batch ? npieces - b0 : batch;
#pragma omp parallel for schedule(dynamic, 1)
        for (int k = 0; k < nb; k++) {
            const int y0 = (b0 + k) * rows, y1 = y0 + rows < h ? y0 + rows : h;
            png_piece(rgb, w, y0, y1, b0 + k == npieces - 1, &pc[k]);
        }
        for (int k = 0; k < nb; k++) {
            if (rc == 0 && !pc[k].ok)
                snprintf(msg, msz, "out of memory compressing the PNG"), rc = -1;
            if (rc == 0)
                rc = png_chunk(fp, "IDAT", pc[k].out, pc[k].len);
            adler = adler32_combine(adler, pc[k].adler, (z_off_t)pc[k].raw);
            free(pc[k].out);
        }
    }
    const unsigned char ztail[4] = {(unsigned char)(adler >> 24), (unsigned char)(adler >> 16),
                                    (unsigned char)(adler >> 8), (unsigned char)adler};
    if (rc == 0)
        rc = png_chunk(fp, "IDAT", ztail, 4) == 0 && png_chunk(fp, "IEND", NULL, 0) == 0 ? 0 : -1;
    free(pc);
    return rc;
}

#endif

static void put_le32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); p[2] = (uint8_t)(v >> 16); p[3] = (uint8_t)(v >> 24);
}

static int write_bmp(FILE *fp, const uint8_t *rgb, int w, int h)
{
    size_t stride = ((size_t)w * 3 + 3) & ~(size_t)3;
    uint8_t hdr[54];
    memset(hdr, 0, sizeof hdr);
    hdr[0] = 'B'; hdr[1] = 'M';
    put_le32(hdr + 2, (uint32_t)(54 + stride * (size_t)h));
    put_le32(hdr + 10, 54);
    put_le32(hdr + 14, 40);
    put_le32(hdr + 18, (uint32_t)w);
    put_le32(hdr + 22, (uint32_t)h); /* positive: rows stored bottom-up */
    hdr[26] = 1;
    hdr[28] = 24;
    put_le32(hdr + 38, 2835); /* 72 dpi */
    put_le32(hdr + 42, 2835);
    if (fwrite(hdr, 1, sizeof hdr, fp) != sizeof hdr)
        return -1;
    uint8_t *row = calloc(stride, 1);
    if (!row)
        return -1;
    for (int y = h - 1; y >= 0; y--) {
        const uint8_t *src = rgb + (size_t)y * (size_t)w * 3;
        for (int x = 0; x < w; x++) {
            row[3 * x + 0] = src[3 * x + 2];
            row[3 * x + 1] = src[3 * x + 1];
            row[3 * x + 2] = src[3 * x + 0];
        }
        if (fwrite(row, 1, stride, fp) != stride) {
            free(row);
            return -1;
        }
    }
    free(row);
    return 0;
}

/* The image in f's file (fmt), then given its name: whole or not at all. */
static int write_into(RtAtomicFile *f, RtImageFormat fmt, const uint8_t *rgb, int w, int h, const char *path,
                      RtError *err)
{
    const int fd2 = dup(f->fd); /* (fclose closes this one; the commit needs f->fd) */
    FILE *fp = fd2 >= 0 ? fdopen(fd2, "wb") : NULL;
    if (!fp) {
        const int e = errno;
        if (fd2 >= 0)
            close(fd2);
        rt_atomic_abort(f);
        return rt_fail(err, "%s: cannot open: %s", path, strerror(e));
    }
    char msg[300] = "write error";
    int rc = 0;
    if (fmt == RT_IMG_PNG) {
#if HAVE_PNG
        rc = write_png(fp, rgb, w, h, msg, sizeof msg);
#else
        snprintf(msg, sizeof msg, "this build has no libpng: write .bmp or .ppm");
        rc = -1;
#endif
    }
    else if (fmt == RT_IMG_BMP)
        rc = write_bmp(fp, rgb, w, h);
    else {
        fprintf(fp, "P6\n%d %d\n255\n", w, h);
        rc = fwrite(rgb, 3, (size_t)w * (size_t)h, fp) == (size_t)w * (size_t)h ? 0 : -1;
    }
    int e = errno;
    if (fflush(fp) != 0 || ferror(fp))
        rc = -1, e = errno;
    if (fclose(fp) != 0 && rc == 0)
        rc = -1, e = errno;
    if (rc != 0) {
        rt_atomic_abort(f);
        if (strcmp(msg, "write error") != 0)
            return rt_fail(err, "%s: %s", path, msg);
        return rt_fail(err, "%s: write failed: %s", path, strerror(e));
    }
    return rt_atomic_commit(f, err);
}

int rt_image_write(const char *path, const uint8_t *rgb, int w, int h, RtError *err)
{
    RtImageFormat fmt = rt_image_format_for(path);
    if (fmt == RT_IMG_UNKNOWN)
        return rt_fail(err, "%s: unknown image format (use .png, .bmp or .ppm)", path);
    RtAtomicFile f;
    if (rt_atomic_open(&f, AT_FDCWD, path, err) != 0)
        return -1;
    return write_into(&f, fmt, rgb, w, h, path, err);
}

#if HAVE_PNG
static int read_png(FILE *fp, const char *path, uint8_t **out, int *w, int *h, RtError *err)
{
    PngErr pe;
    pe.msg[0] = '\0';
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &pe, png_error_cb, png_warn_cb);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    uint8_t *volatile buf = NULL;
    png_bytep *volatile rows = NULL; /* volatile: freed after a longjmp from libpng */
    if (!png || !info) {
        png_destroy_read_struct(&png, &info, NULL);
        return rt_fail(err, "%s: libpng: cannot create reader", path);
    }
    if (setjmp(pe.jb)) {
        png_destroy_read_struct(&png, &info, NULL);
        free(buf);
        free(rows);
        return rt_fail(err, "%s: libpng: %s", path, pe.msg);
    }
    png_init_io(png, fp);
    png_read_info(png, info);
    png_uint_32 pw = png_get_image_width(png, info), ph = png_get_image_height(png, info);
    if (pw == 0 || ph == 0 || pw > RT_MAX_SIDE || ph > RT_MAX_SIDE) {
        png_destroy_read_struct(&png, &info, NULL);
        return rt_fail(err, "%s: unsupported size %ux%u", path, (unsigned)pw, (unsigned)ph);
    }
    /* Normalize every PNG to 8-bit RGB. */
    png_set_strip_16(png);
    png_set_strip_alpha(png);
    png_set_packing(png);
    png_set_palette_to_rgb(png);
    png_set_expand_gray_1_2_4_to_8(png);
    png_set_gray_to_rgb(png);
    png_read_update_info(png, info);
    if (png_get_rowbytes(png, info) != (size_t)pw * 3) {
        png_destroy_read_struct(&png, &info, NULL);
        return rt_fail(err, "%s: unsupported PNG layout", path);
    }
    buf = malloc((size_t)pw * ph * 3);
    rows = malloc(ph * sizeof *rows);
    if (!buf || !rows) {
        free(rows);
        png_destroy_read_struct(&png, &info, NULL);
        free(buf);
        return rt_fail(err, "%s: out of memory", path);
    }
    for (png_uint_32 y = 0; y < ph; y++)
        rows[y] = buf + (size_t)y * pw * 3;
    png_read_image(png, rows);
    free(rows);
    png_destroy_read_struct(&png, &info, NULL);
    *out = buf;
    *w = (int)pw;
    *h = (int)ph;
    return 0;
}

#endif

static uint32_t get_le32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

int rt_image_read(const char *path, uint8_t **out, int *w, int *h, RtError *err)
{
    FILE *fp = fopen(path, "rb");
    if (!fp)
        return rt_fail(err, "%s: cannot open: %s", path, strerror(errno));
    uint8_t sig[8];
    size_t got = fread(sig, 1, 8, fp);
    rewind(fp);
    int rc;
    if (got == 8 && memcmp(sig, "\x89PNG\r\n\x1a\n", 8) == 0) {
#if HAVE_PNG
        rc = read_png(fp, path, out, w, h, err);
#else
        rc = rt_fail(err, "%s: this build has no libpng to read PNG", path);
#endif
    } else if (got >= 2 && sig[0] == 'B' && sig[1] == 'M') {
        uint8_t hdr[54];
        rc = -1;
        if (fread(hdr, 1, 54, fp) == 54 && get_le32(hdr + 14) >= 40 && hdr[28] == 24) {
            int64_t bw = (int32_t)get_le32(hdr + 18), bh = (int32_t)get_le32(hdr + 22);
            int flip = bh > 0;
            bh = bh < 0 ? -bh : bh; /* in 64 bits: -INT32_MIN does not overflow */
            if (bw > 0 && bh > 0 && bw <= RT_MAX_SIDE && bh <= RT_MAX_SIDE &&
                fseek(fp, (long)get_le32(hdr + 10), SEEK_SET) == 0) {
                size_t stride = ((size_t)bw * 3 + 3) & ~(size_t)3;
                uint8_t *buf = malloc((size_t)bw * bh * 3), *row = malloc(stride);
                rc = buf && row ? 0 : -1;
                for (int y = 0; rc == 0 && y < bh; y++) {
                    if (fread(row, 1, stride, fp) != stride) {
                        rc = -1;
                        break;
                    }
                    uint8_t *dst = buf + (size_t)(flip ? bh - 1 - y : y) * bw * 3;
                    for (int x = 0; x < bw; x++) {
                        dst[3 * x] = row[3 * x + 2];
                        dst[3 * x + 1] = row[3 * x + 1];
                        dst[3 * x + 2] = row[3 * x];
                    }
                }
                free(row);
                if (rc == 0) {
                    *out = buf; *w = (int)bw; *h = (int)bh;
                } else {
                    free(buf);
                }
            }
        }
        if (rc != 0)
            rt_fail(err, "%s: not a 24-bit BMP this reader understands", path);
    } else if (got >= 2 && sig[0] == 'P' && sig[1] == '6') {
        int pw = 0, ph = 0, maxv = 0;
        rc = -1;
        if (fscanf(fp, "P6 %d %d %d", &pw, &ph, &maxv) == 3 && maxv == 255 && pw > 0 && ph > 0 &&
            pw <= RT_MAX_SIDE && ph <= RT_MAX_SIDE && fgetc(fp) != EOF) {
            uint8_t *buf = malloc((size_t)pw * ph * 3);
            if (buf && fread(buf, 3, (size_t)pw * ph, fp) == (size_t)pw * ph) {
                *out = buf; *w = pw; *h = ph;
                rc = 0;
            } else {
                free(buf);
            }
        }
        if (rc != 0)
            rt_fail(err, "%s: not a binary 8-bit PPM this reader understands", path);
    } else {
        rc = rt_fail(err, "%s: not a PNG, BMP or PPM image", path);
    }
    fclose(fp);
    return rc;
}
