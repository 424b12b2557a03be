/* main.c: `harness COMMAND [OPTIONS]`: dispatch to the sub-commands. */
#include "hx.h"

#include "config.h"

#include <string.h>

static void usage(FILE *f)
{
    fputs("usage: harness COMMAND [OPTIONS] ...\n"
          "raybench benchmarking harness " RT_VERSION ": runs raytrace, or any program, as a\n"
          "child process, one CSV row per run, then tables, plots and regression checks.\n\n"
          "commands:\n"
          "  run CONFIG [-o FILE.csv]   execute a study (--dry-run, --resume)\n"
          "  table CSV                  statistics, speedups, Amdahl fit, cross table\n"
          "  plot CSV -o PREFIX         gnuplot PNG + SVG (scripts and data kept)\n"
          "  report CSV... -o DIR       one self-contained HTML page: tables, plots, provenance\n"
          "  compare NEW.csv BASE.csv   regression check (exit 1 on regression)\n"
          "  ab 'COMMAND A' 'COMMAND B' the two commands interleaved, and the verdict\n"
          "  ceiling CONFIG             the machine's own ceiling for the study's efficiency\n"
          "  topo [CONFIG]              hwloc topology and planned cores per run\n"
          "  slurm CONFIG [-o FILE]     sbatch script running the study with srun\n"
          "  history add|show|plot|check|publish  performance across commits (SQLite)\n\n"
          "`harness COMMAND --help` describes each command; docs/harness.md has the\n"
          "config format and CSV schema.\n", f);
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        usage(stderr);
        return 1;
    }
    const char *cmd = argv[1];
    if (strcmp(cmd, "-h") == 0 || strcmp(cmd, "--help") == 0 || strcmp(cmd, "help") == 0) {
        usage(stdout);
        return 0;
    }
    if (strcmp(cmd, "--version") == 0) {
        printf("harness %s\n", RT_VERSION);
        return 0;
    }
    static const struct {
        const char *name;
        int (*fn)(int, char **);
    } cmds[] = {{"run", hx_cmd_run}, {"table", hx_cmd_table}, {"plot", hx_cmd_plot},
                {"compare", hx_cmd_compare}, {"topo", hx_cmd_topo},
                {"slurm", hx_cmd_slurm}, {"history", hx_cmd_history}, {"ab", hx_cmd_ab},
                {"ceiling", hx_cmd_ceiling}, {"report", hx_cmd_report}};
    for (size_t i = 0; i < sizeof cmds / sizeof cmds[0]; i++)
        if (strcmp(cmd, cmds[i].name) == 0)
            return cmds[i].fn(argc - 1, argv + 1);
    fprintf(stderr, "harness: unknown command '%s' (try harness --help)\n", cmd);
    return 1;
}
