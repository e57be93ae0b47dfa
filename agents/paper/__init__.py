"""The paper's §6 scenario: planned (no simulator) and simulated runs, their metrics, Figs. 4-9."""

from agents.paper.simulation import PaperRun, PaperRunConfig, run_paper_sim, write_paper_outputs

__all__ = ["PaperRun", "PaperRunConfig", "run_paper_sim", "write_paper_outputs"]
