/* test_main.c - runs every C test; last line "N passed, N failed". */
#include "test.h"

int t_passed, t_failed, t_case_bad;
const char *t_case;

int t_begin(const char *name)
{
    t_case = name;
    t_case_bad = 0;
    th_fresh();
    return 1;
}

int t_end(void)
{
    if (t_case_bad)
        t_failed++;
    else
        t_passed++;
    return 0;
}

void t_fail(const char *what, const char *file, int line)
{
    if (!t_case_bad)
        printf("FAIL: %s\n", t_case);
    printf("    %s:%d: %s\n", file, line, what);
    t_case_bad = 1;
}

int main(void)
{
    test_mb();
    test_vectors();
    test_seq();
    test_safe();
    test_nvm();
    printf("%d passed, %d failed\n", t_passed, t_failed);
    return t_failed ? 1 : 0;
}
