/* The two JSON writers every JSON output of the project shares (summary.json,
 * the run records, --print-config=json): a string, escaped, and a number. */
#ifndef CM_JSON_H
#define CM_JSON_H

#include <stdio.h>

/* "s" with '"' and '\' escaped and control characters as \u00XX (NULL as ""). */
void cm_json_string(FILE *f, const char *s);
/* %.17g (reads back bit for bit; an integral value prints as an integer), or
 * null for a value JSON cannot hold (infinite, NaN). */
void cm_json_number(FILE *f, double v);

#endif
