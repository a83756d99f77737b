"""The report page's look: its CSS (screen and A4 print rules), the script that keeps the first page
on one printed page, and the HTML page around a report's body (:mod:`tcr_accuracy.view.report`)."""

CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: #1d1d1f;
  max-width: 1100px; margin: 24px auto; padding: 0 18px; line-height: 1.45; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; margin-top: 1.6em; border-bottom: 1px solid #ddd; padding-bottom: 0.2em; }
.meta, .note, figcaption { color: #555; font-size: 0.9em; }
/* nothing wider than the page: tables shrink to it and break long words (paths, parameter
   names) anywhere, printed text wraps its long lines */
table { border-collapse: collapse; margin: 0.6em 0; font-variant-numeric: tabular-nums; max-width: 100%; }
th, td { border: 1px solid #ccc; padding: 4px 10px; text-align: right; overflow-wrap: normal; }
span.long { overflow-wrap: anywhere; }
th { background: #f0f2f5; }
td:first-child, th:first-child { text-align: left; }
tbody tr:nth-child(even) { background: #fafafa; }
figure { margin: 1em 0; }
img { max-width: 100%; box-sizing: border-box; border: 1px solid #e3e3e3; }
iframe { width: 100%; box-sizing: border-box; border: 1px solid #ccc; }
pre { max-width: 100%; box-sizing: border-box; white-space: pre-wrap; overflow-wrap: anywhere; }
pre.command { background: #f5f5f5; padding: 8px 10px; }
pre.printed { background: #f7f7f7; border: 1px solid #e3e3e3; padding: 8px 10px;
  font-size: 0.82em; line-height: 1.3; }
code { overflow-wrap: anywhere; }
.print-only { display: none; }
a { overflow-wrap: anywhere; }

/* the calibration report's first page */
.first-page { border: 1px solid #d0d4da; padding: 4px 22px 16px; margin-bottom: 2em; }
.first-page h1 { margin-top: 0.5em; }
.first-page h2 { font-size: 1.05em; margin-top: 1.1em; }
.first-page table { width: 100%; }
.first-page table.facts th { width: 10%; text-align: left; vertical-align: top; }
.first-page table.facts td { text-align: left; vertical-align: top; width: 52%; }
.first-page table.facts td + th + td { width: 28%; }
.first-page table.facts td.wide { width: auto; }
.first-page p.verdict { border: 2px solid #888; padding: 4px 8px; margin: 0.5em 0; }
.first-page p.verdict.pass { border-color: #2e7d32; background: #eef7ee; }
.first-page p.verdict.fail { border-color: #c62828; background: #fdeeee; }
.first-page td.text, .first-page th.text { text-align: left; }
.first-page ul { margin: 0.3em 0; padding-left: 1.3em; }
.first-page .command { font-family: ui-monospace, "DejaVu Sans Mono", monospace; font-size: 0.9em;
  background: #f5f5f5; padding: 1px 4px; overflow-wrap: anywhere; }
.table.wide table { font-size: 0.8em; }
.table.wide th, .table.wide td { padding: 3px 5px; }
table.signatures { margin-top: 1em; }
table.signatures th { width: 50%; text-align: left; }
table.signatures td { height: 3.2em; text-align: left; vertical-align: bottom; color: #888; font-size: 0.85em; }

@page { size: A4; margin: 11mm 12mm 12mm;
  @bottom-right { content: "page " counter(page) " of " counter(pages); font-size: 7.5pt; color: #555; } }

@media print {
  body { max-width: none; margin: 0; padding: 0; font-size: 9pt; line-height: 1.3; }
  .first-page { border: none; padding: 0; margin: 0; break-after: page; page-break-after: always;
    font-size: 8.5pt; line-height: 1.22; zoom: var(--print-zoom, 1); }
  .first-page h1 { font-size: 14pt; margin: 0 0 0.1em; }
  .first-page h2 { font-size: 10pt; margin: 0.6em 0 0.15em; }
  .first-page p, .first-page ul { margin: 0.25em 0; }
  .first-page table { margin: 0.3em 0; }
  .first-page th, .first-page td { padding: 1px 5px; }
  .first-page p.note { font-size: 7.5pt; }
  table.signatures td { height: 3.6em; }
  th, td { padding: 2px 6px; }
  .table.wide table { font-size: 7pt; }
  .table.wide th, .table.wide td { padding: 1px 3px; }
  figure, pre.command, ul, .first-page table { break-inside: avoid; page-break-inside: avoid; }
  /* a long table starts on the page its heading is on and runs on, row by row, its head repeated
     (kept whole, the parameter table left page 2 blank but for the part's heading) */
  tr { break-inside: avoid; page-break-inside: avoid; }
  thead { display: table-header-group; }
  h1, h2, h3 { break-after: avoid; page-break-after: avoid; }
  pre.printed { font-size: 7pt; }
  img { max-height: 200mm; }
  figure.scene iframe, figure.scene figcaption { display: none; }
  .print-only { display: block; }
  a { color: inherit; text-decoration: none; }
  tbody tr:nth-child(even) { background: none; }
}
"""

#: The printable area of A4 at the ``@page`` margins in CSS px (96 per inch): 186 x 274 mm.
PRINT_WIDTH_PX = round((210 - 12 - 12) / 25.4 * 96)
PRINT_HEIGHT_PX = (297 - 11 - 12) / 25.4 * 96

# The first page stays one page when printed, whatever its fonts make of the estimate it was cut
# to (tcr_accuracy.view.page_blocks.fit_page): the page lays the first page out as printed (the
# print rules on, the printable width) and measures it; when it is taller than the printable
# height it scales it down (CSS zoom, used by the print rules only) until it fits, no further than
# 0.8. It runs when the page loads (Chromium's print to PDF included) and before printing.
FIT_FIRST_PAGE_SCRIPT = """<script>
(function () {
  var page = document.querySelector(".first-page");
  if (!page) { return; }
  function printRules() {
    var found = [];
    for (var i = 0; i < document.styleSheets.length; i++) {
      var rules = document.styleSheets[i].cssRules;
      for (var k = 0; k < rules.length; k++) {
        if (rules[k].media && rules[k].media.mediaText === "print") { found.push(rules[k]); }
      }
    }
    return found;
  }
  function height() {
    var last = page.lastElementChild || page;
    return last.getBoundingClientRect().bottom - page.getBoundingClientRect().top;
  }
  function fit() {
    var rules = printRules(), body = document.body, width = body.style.width, zoom = 1;
    rules.forEach(function (r) { r.media.mediaText = "all"; });
    body.style.width = "PRINT_WIDTHpx";
    page.style.setProperty("--print-zoom", "1");
    for (var k = 0; k < 12 && height() > PRINT_HEIGHT && zoom > 0.8; k++) {
      zoom = Math.max(0.8, zoom * Math.min(0.98, PRINT_HEIGHT / height()));
      page.style.setProperty("--print-zoom", String(zoom));
    }
    page.setAttribute("data-print-zoom", zoom.toFixed(3));
    body.style.width = width;
    rules.forEach(function (r) { r.media.mediaText = "print"; });
  }
  fit();
  window.addEventListener("beforeprint", fit);
})();
</script>""".replace("PRINT_WIDTH", str(PRINT_WIDTH_PX)).replace("PRINT_HEIGHT", f"{PRINT_HEIGHT_PX - 6:.0f}")

PAGE_TEMPLATE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{title}</title>
<style>{css}</style>
</head>
<body>
{body}
</body>
</html>
"""


__all__ = ["CSS", "FIT_FIRST_PAGE_SCRIPT", "PAGE_TEMPLATE", "PRINT_HEIGHT_PX", "PRINT_WIDTH_PX"]
