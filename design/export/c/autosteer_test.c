/* Replays test_vectors.csv (design export --format c) through as_step and reports the largest
 * difference from the Python controller's command.
 *
 *   cc -std=c99 -O2 -o autosteer_test autosteer_test.c autosteer_step.c -lm
 *   ./autosteer_test test_vectors.csv 1e-12      # exit 0 if every |difference| <= 1e-12 rad/s
 *
 * Each data row: reset (1 = as_reset before this step), cross_track, heading_error,
 * wheel_angle, speed, the Python command. Lines starting with '#' and the header are skipped.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "autosteer_step.h"

int main(int argc, char **argv)
{
    FILE *f;
    char line[1024];
    double tol, worst = 0.0;
    long rows = 0;
    as_state s;

    if (argc != 3) {
        fprintf(stderr, "usage: %s test_vectors.csv TOLERANCE\n", argv[0]);
        return 2;
    }
    tol = strtod(argv[2], NULL);
    f = fopen(argv[1], "r");
    if (f == NULL) {
        fprintf(stderr, "cannot open %s\n", argv[1]);
        return 2;
    }
    as_reset(&s);
    while (fgets(line, sizeof line, f) != NULL) {
        int reset;
        double ct, he, wa, v, want, got, d;
        if (line[0] == '#' || line[0] == 'r') {
            continue;
        }
        if (sscanf(line, "%d,%lf,%lf,%lf,%lf,%lf", &reset, &ct, &he, &wa, &v, &want) != 6) {
            fprintf(stderr, "bad row %ld: %s", rows + 1, line);
            fclose(f);
            return 2;
        }
        if (reset) {
            as_reset(&s);
        }
        got = as_step(&s, ct, he, wa, v);
        d = fabs(got - want);
        if (!(d <= worst)) {
            worst = d;
        }
        ++rows;
    }
    fclose(f);
    printf("rows %ld max_abs_difference %.17g\n", rows, worst);
    return (rows > 0 && worst <= tol) ? 0 : 1;
}
