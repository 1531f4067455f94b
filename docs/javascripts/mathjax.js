// MathJax 3 for pymdownx.arithmatex (generic mode: \( \) and \[ \] in elements of class
// "arithmatex"), as in mkdocs-material's documentation, and for the notebooks' Markdown
// cells (mkdocs-jupyter leaves their $ and $$ as written, in "jp-RenderedMarkdown").
// Every element with a class is ignored unless it is one of those (their children without
// a class are not), so a $ elsewhere on a page stays a dollar.
window.MathJax = {
  tex: {
    inlineMath: [["\\(", "\\)"], ["$", "$"]],
    displayMath: [["\\[", "\\]"], ["$$", "$$"]],
    processEscapes: true,
    processEnvironments: true,
  },
  options: {
    ignoreHtmlClass: ".+",
    processHtmlClass: "arithmatex|jp-RenderedMarkdown",
  },
};

document$.subscribe(() => {
  MathJax.startup.output.clearCache();
  MathJax.typesetClear();
  MathJax.texReset();
  MathJax.typesetPromise();
});
