"""Helpers for driving a study's pages: the organiser's, and a participant's."""

from __future__ import annotations

from typing import Any

from playwright.sync_api import Page, expect

BUDGET_S = 30
"""Each participant's budget: long enough to consent and reward on a busy machine."""
CODE = "C0DE42"


def create_study(page: Page, budget_s: int = BUDGET_S, questions: tuple[str, ...] = ()) -> None:
    """Make study "pilot" on the organiser's page, a refused field said beside it first."""
    form = page.locator("#new-study-form")
    form.locator('[name="name"]').fill("pilot")
    form.locator('[name="conditions"]').fill("trainer, rp")
    form.locator('[name="budget"]').fill(str(budget_s))
    form.locator('[name="budget_unit"]').select_option("seconds")
    form.locator('[name="consent_text"]').fill("You will train a simulated robot.")
    form.locator('[name="consent_version"]').fill("v1")
    form.locator('[name="completion_code"]').fill(CODE)
    form.locator('[name="questionnaire"]').fill("\n".join(questions))
    # The API refuses a redirect that is not http(s): beside that field, and nothing made.
    form.locator('[name="redirect_url"]').fill("ftp://example.org")
    form.locator('button[type="submit"]').click()
    refused = page.locator("label.invalid:has(input[name='redirect_url']) .field-error")
    expect(refused).to_contain_text("match pattern")
    expect(page.locator("#studies-list")).to_be_visible()
    expect(page.locator('#studies-list tr[data-study="pilot"]')).to_have_count(0)
    form.locator('[name="redirect_url"]').fill("")
    expect(page.locator("label.invalid")).to_have_count(0)
    form.locator('button[type="submit"]').click()
    expect(page.locator('#studies-list tr[data-study="pilot"]')).to_be_visible()


def invite(page: Page, ids: list[str]) -> list[str]:
    """Invite participants by recruiters' ids on the organiser's page: their links."""
    form = page.locator("#invite-form")
    expect(form.locator('[name="study"]')).to_have_value("pilot")
    form.locator('[name="external_ids"]').fill("\n".join(ids))
    form.locator('button[type="submit"]').click()
    links = page.locator("#invited input.link")
    expect(links).to_have_count(len(ids))
    expect(page.locator("#invited")).to_contain_text("shown this once")
    return [links.nth(i).input_value() for i in range(len(ids))]


def reward(page: Page, press: str) -> dict[str, Any]:
    """Press + or - (the key, or the button) and answer the service's acknowledgement."""
    with page.expect_response(
        lambda r: r.request.method == "POST" and r.url.endswith("/rewards")
    ) as answer:
        if press in "+-":
            page.keyboard.press("+" if press == "+" else "-")
        else:
            page.click(press)
    response = answer.value
    assert response.status == 202, response.text()
    ack: dict[str, Any] = response.json()
    return ack


def consent(page: Page, link: str) -> int:
    """Open the link, read the consent, agree: answers the participant's run."""
    page.goto(link)
    page.wait_for_selector("body[data-ready=true]")
    expect(page.locator("#consent-text")).to_have_text("You will train a simulated robot.")
    expect(page.locator("#consent-version")).to_contain_text("v1")
    # A participant sees neither the tabs nor run control, nor the token button.
    for hidden in ("#tab-editor", "#run-start", "#new-run", "#view3d", "#token-button"):
        expect(page.locator(hidden)).to_be_hidden()
    with page.expect_response(lambda r: r.url.endswith("/api/participant/consent")) as answer:
        page.click("#consent-agree")
    run_id: int = answer.value.json()["run_id"]
    expect(page.locator("#view-console")).to_be_visible()
    expect(page.locator("#run-status")).to_have_text("running")
    expect(page.locator("#reward-plus")).to_be_enabled()
    expect(page.locator("#view2d-toggle")).to_be_hidden()
    return run_id
