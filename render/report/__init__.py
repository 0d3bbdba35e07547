"""Contact-area reports (`orthosim report`): a self-contained page, its data and a PDF per set of runs.

`runs` reads finished run folders, `gather` computes a case's figures once per pose, `pictures`
renders the contact areas and distance maps, `figures` draws the plots, `page` writes index.html
and report.json from one template, `browser` prints the PDF and checks the page in headless Chromium,
`regression_page` the CI page of an image-regression run.
"""
