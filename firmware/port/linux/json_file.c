#define _GNU_SOURCE
#include "json_file.h"

#include <errno.h>
#include <string.h>
#include <unistd.h>

int json_file_open(json_file_t *j, const char *path, const char *option, char *err, size_t errcap)
{
    snprintf(j->path, sizeof(j->path), "%s", path);
    snprintf(j->tmp, sizeof(j->tmp), "%s.tmp.%ld", j->path, (long)getpid());
    j->f = fopen(j->tmp, "w");
    if (j->f == NULL) {
        snprintf(err, errcap, "%s: cannot write '%.600s': %s", option, j->tmp, strerror(errno));
        return -1;
    }
    return 0;
}

int json_file_commit(json_file_t *j, const char *option, char *err, size_t errcap)
{
    const int bad = ferror(j->f);
    if (fclose(j->f) != 0 || bad || rename(j->tmp, j->path) != 0) {
        snprintf(err, errcap, "%s: cannot write '%.600s': %s", option, j->path, strerror(errno));
        unlink(j->tmp);
        return -1;
    }
    return 0;
}

void json_string(FILE *f, const char *s)
{
    fputc('"', f);
    for (; *s != '\0'; ++s) {
        if (*s == '"' || *s == '\\') {
            fputc('\\', f);
            fputc(*s, f);
        } else if ((unsigned char)*s < 0x20u) {
            fprintf(f, "\\u%04x", (unsigned)(unsigned char)*s);
        } else {
            fputc(*s, f);
        }
    }
    fputc('"', f);
}
