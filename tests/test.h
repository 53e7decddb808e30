/* Minimal test harness shared by all test programs (as Box2D's): a test is a
 * plain `int name(void)` returning 0 on success; ENSURE* report the file,
 * line and the values involved, then fail the test.
 *
 * A test program lists its tests in a table and calls test_main():
 *   static const test_case tests[] = {{"hertz_wall", hertz_wall}, ...};
 *   int main(int argc, char **argv) { return test_main(argc, argv, tests, TEST_COUNT(tests)); }
 * Run one test by naming it: ./test_dem hertz_wall  (ctest does this per case).
 * The tests[] table is the one list of a program's cases: CMake registers
 * each entry in ctest (demfem_add_test_table, tests/CMakeLists.txt).
 * Cases that only measure (they print figures a tolerance was chosen from and
 * assert nothing) are not tests: they sit in a second table, run only when
 * named, through test_main_measure(). */
#ifndef DEMFEM_TEST_H
#define DEMFEM_TEST_H

#include <math.h>
#include <stdio.h>
#include <string.h>

typedef struct test_case {
    const char *name;
    int (*fn)(void);
} test_case;

#define TEST_COUNT(a) ((int)(sizeof(a) / sizeof((a)[0])))

#define ENSURE(cond)                                                                          \
    do {                                                                                      \
        if (!(cond)) {                                                                        \
            fprintf(stderr, "%s:%d: ENSURE(%s) failed\n", __FILE__, __LINE__, #cond);         \
            return 1;                                                                         \
        }                                                                                     \
    } while (0)

#define ENSURE_MSG(cond, ...)                                                                 \
    do {                                                                                      \
        if (!(cond)) {                                                                        \
            fprintf(stderr, "%s:%d: ENSURE(%s) failed: ", __FILE__, __LINE__, #cond);         \
            fprintf(stderr, __VA_ARGS__);                                                     \
            fputc('\n', stderr);                                                              \
            return 1;                                                                         \
        }                                                                                     \
    } while (0)

/* |a - b| <= tol */
#define ENSURE_NEAR(a, b, tol)                                                                \
    do {                                                                                      \
        double ea_ = (a), eb_ = (b), et_ = (tol);                                             \
        if (!(fabs(ea_ - eb_) <= et_)) {                                                      \
            fprintf(stderr, "%s:%d: |%s - %s| = |%.10g - %.10g| = %.3g > %.3g\n", __FILE__,   \
                    __LINE__, #a, #b, ea_, eb_, fabs(ea_ - eb_), et_);                         \
            return 1;                                                                         \
        }                                                                                     \
    } while (0)

/* |a - b| <= rel * |b| : b is the reference (closed-form) value */
#define ENSURE_REL(a, b, rel)                                                                 \
    do {                                                                                      \
        double ea_ = (a), eb_ = (b), er_ = (rel);                                             \
        if (!(fabs(ea_ - eb_) <= er_ * fabs(eb_))) {                                          \
            fprintf(stderr, "%s:%d: %s = %.10g vs %s = %.10g: relative error %.3g > %.3g\n",  \
                    __FILE__, __LINE__, #a, ea_, #b, eb_, fabs(ea_ - eb_) / fabs(eb_), er_);   \
            return 1;                                                                         \
        }                                                                                     \
    } while (0)

static inline int test_main_measure(int argc, char **argv, const test_case *tests, int n,
                                    const test_case *measurements, int n_measurements)
{
    int failed = 0, ran = 0;
    for (int i = 0; i < n_measurements && argc > 1; i++)
        for (int a = 1; a < argc; a++)
            if (strcmp(argv[a], measurements[i].name) == 0) {
                ran++;
                int rc = measurements[i].fn();
                printf("%s %s (measurement)\n", rc ? "FAIL" : "done", measurements[i].name);
                fflush(stdout);
                failed += rc != 0;
                break;
            }
    for (int i = 0; i < n; i++) {
        if (argc > 1) {
            int want = 0;
            for (int a = 1; a < argc; a++)
                want |= strcmp(argv[a], tests[i].name) == 0;
            if (!want)
                continue;
        }
        ran++;
        int rc = tests[i].fn();
        printf("%s %s\n", rc ? "FAIL" : "ok  ", tests[i].name);
        fflush(stdout);
        failed += rc != 0;
    }
    if (ran == 0) {
        fprintf(stderr, "no test matched\n");
        return 2;
    }
    return failed ? 1 : 0;
}

static inline int test_main(int argc, char **argv, const test_case *tests, int n)
{
    return test_main_measure(argc, argv, tests, n, NULL, 0);
}

#endif
