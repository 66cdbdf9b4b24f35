// MathJax 3 for pymdownx.arithmatex (generic mode), served from this site (no CDN).
window.MathJax = {
  tex: {
    inlineMath: [["\\(", "\\)"]],
    displayMath: [["\\[", "\\]"]],
    processEscapes: true,
    processEnvironments: true,
  },
  options: {
    ignoreHtmlClass: ".*|",
    processHtmlClass: "arithmatex",
  },
};

// MathJax typesets the page when it loads. With Material's instant navigation a new page's
// content arrives without a reload: typeset it then (document$ emits once per page; the
// first emission is the initial load, already handled by MathJax's startup).
let lpFirstPage = true;
document$.subscribe(() => {
  if (lpFirstPage) {
    lpFirstPage = false;
    return;
  }
  if (window.MathJax && MathJax.typesetPromise) {
    MathJax.typesetClear();
    MathJax.texReset();
    MathJax.typesetPromise();
  }
});
