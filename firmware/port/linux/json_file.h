/* A JSON summary file written so that a reader never sees half of it: into PATH.tmp.PID, then
 * renamed over PATH. Shared by the controller's and the simulator's summaries. */
#ifndef ARM_JSON_FILE_H
#define ARM_JSON_FILE_H

#include <stddef.h>
#include <stdio.h>

typedef struct {
    FILE *f;
    char path[1024];
    char tmp[1100];
} json_file_t;

/* 0 and j->f open for writing, or -1 with a message naming `option` and the path in err. */
int json_file_open(json_file_t *j, const char *path, const char *option, char *err, size_t errcap);
/* Closes and renames into place: 0, or -1 (the temporary file removed) with a message in err. */
int json_file_commit(json_file_t *j, const char *option, char *err, size_t errcap);
/* s as a JSON string literal (quotes, backslashes and control characters escaped). */
void json_string(FILE *f, const char *s);

#endif
