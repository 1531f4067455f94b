"""The paper's figures and the reproduction report."""
