/* Runs the controller step against a log written by chewbot (a simulation of the same controller), checks the
   commanded torques against the logged ones, and prints the time per step.
   Usage: example LOG [REPEATS]  (LOG: t, theta1..6, tau_cmd1..6 per line after a header). Exit 1 on a mismatch.
   The check: |tau_cmd - logged| <= 1e-9 * max |logged| on every tick. REPEATS runs the whole log that many
   times for the timing (median, p99 and maximum over every step). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "chewbot_ctrl.h"

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int by_value(const void* a, const void* b) {
  double x = *(const double*)a, y = *(const double*)b;
  return (x > y) - (x < y);
}

int main(int argc, char** argv) {
  FILE* f;
  char line[4096];
  double* rows = NULL;
  double* times;
  long n = 0, capacity = 0, k, r, repeats, bad = 0, count;
  double scale = 0.0, worst = 0.0;
  static chewbot_ctrl ctx;
  if (argc < 2) { fprintf(stderr, "usage: %s LOG [REPEATS]\n", argv[0]); return 2; }
  repeats = argc > 2 ? atol(argv[2]) : 1;
  if (repeats < 1) repeats = 1;
  f = fopen(argv[1], "r");
  if (!f) { perror(argv[1]); return 2; }
  if (!fgets(line, sizeof line, f)) { fprintf(stderr, "%s: empty\n", argv[1]); return 2; }
  while (fgets(line, sizeof line, f)) {
    double* row;
    char* p = line;
    int j;
    if (n == capacity) {
      capacity = capacity ? 2 * capacity : 1024;
      rows = realloc(rows, (size_t)capacity * 13 * sizeof *rows);
      if (!rows) { fprintf(stderr, "out of memory\n"); return 2; }
    }
    row = rows + 13 * n;
    for (j = 0; j < 13; ++j) {
      char* end;
      row[j] = strtod(p, &end);
      if (end == p) { fprintf(stderr, "%s: line %ld: 13 numbers expected\n", argv[1], n + 2); return 2; }
      p = *end == ',' ? end + 1 : end;
    }
    for (j = 7; j < 13; ++j) if (fabs(row[j]) > scale) scale = fabs(row[j]);
    ++n;
  }
  fclose(f);
  if (n == 0) { fprintf(stderr, "%s: no rows\n", argv[1]); return 2; }
  times = malloc((size_t)(n * repeats) * sizeof *times);
  if (!times) { fprintf(stderr, "out of memory\n"); return 2; }
  for (r = 0; r < repeats; ++r) {
    chewbot_ctrl_init(&ctx, rows[0], NULL);
    for (k = 0; k < n; ++k) {
      const double* row = rows + 13 * k;
      double tau[6], t0;
      unsigned status;
      int j;
      t0 = now();
      chewbot_ctrl_step(&ctx, row[0], row + 1, tau, &status);
      times[r * n + k] = now() - t0;
      if (r == 0) {
        for (j = 0; j < 6; ++j) {
          double d = fabs(ctx.out.tau_cmd[j] - row[7 + j]);
          if (d > worst) worst = d;
          if (d > 1e-9 * scale) {
            if (bad < 5) fprintf(stderr, "t = %.6f s: tau_cmd%d = %.17g, the log %.17g\n", row[0], j + 1, ctx.out.tau_cmd[j], row[7 + j]);
            ++bad;
          }
        }
      }
    }
  }
  count = n * repeats;
  qsort(times, (size_t)count, sizeof *times, by_value);
  printf("steps %ld, largest difference from the log %.3g N m (%.3g of max |tau| %.4g N m)\n", n, worst, worst / scale, scale);
  printf("time per step over %ld steps: median %.2f us, p99 %.2f us, max %.2f us\n", count, 1e6 * times[count / 2],
         1e6 * times[(long)(0.99 * (double)(count - 1))], 1e6 * times[count - 1]);
  free(rows);
  free(times);
  if (bad) { fprintf(stderr, "%ld torques differ from the log by more than 1e-9 of max |tau|\n", bad); return 1; }
  printf("all torques equal the log's to 1e-9 of max |tau|\n");
  return 0;
}
