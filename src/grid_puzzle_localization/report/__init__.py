"""The experiment report: report.md (our figures next to the paper's) and PNG plots, rendered from
the summary and the per-mode outputs. Plots use matplotlib's Agg backend (no display needed)."""
