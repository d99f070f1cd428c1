"""Figures of the paper's tables from recorded results: `python -m paper_figs`
(paper_figs/make_figs.py)."""
