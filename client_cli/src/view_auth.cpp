#include "view_auth.hpp"

#include <civetweb.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <string_view>

#include "client/status_json.hpp"

namespace facescan::client::detail {
namespace {

constexpr int kMaxFormBytes = 4096;  // a user name and a password; anything longer is refused unread

void send(mg_connection* conn, int status, const char* mime, std::string_view body,
          const std::vector<std::pair<std::string, std::string>>& headers = {}) {
    mg_response_header_start(conn, status);
    mg_response_header_add(conn, "Content-Type", mime, -1);
    mg_response_header_add(conn, "Cache-Control", "no-store", -1);
    mg_response_header_add(conn, "Content-Length", std::to_string(body.size()).c_str(), -1);
    for (const auto& [name, value] : headers) mg_response_header_add(conn, name.c_str(), value.c_str(), -1);
    mg_response_header_send(conn);
    const mg_request_info* ri = mg_get_request_info(conn);
    if (std::strcmp(ri->request_method, "HEAD") != 0 && !body.empty()) mg_write(conn, body.data(), body.size());
}

std::string htmlEscape(const std::string& s) {
    std::string out;
    for (const char c : s) {
        switch (c) {
            case '<': out += "&lt;"; break;
            case '>': out += "&gt;"; break;
            case '&': out += "&amp;"; break;
            case '"': out += "&quot;"; break;
            default: out += c;
        }
    }
    return out;
}

// The whole page inline (no script, no other file): it is all a browser without a session may load.
int sendLoginPage(mg_connection* conn, int status, const std::string& message,
                  const std::vector<std::pair<std::string, std::string>>& extra = {}) {
    const std::string page =
        "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>facescan: log in</title>"
        "<meta name=\"viewport\" content=\"width=device-width\"><style>body{font-family:sans-serif;background:#1b1d22;"
        "color:#ddd;display:flex;justify-content:center;margin-top:15vh}form{display:grid;gap:.6em;width:18em}"
        "input,button{font-size:1em;padding:.4em}p.err{color:#f88}</style></head><body>"
        "<form method=\"post\" action=\"/login\"><h1>facescan viewer</h1>" +
        (message.empty() ? std::string() : "<p class=\"err\">" + htmlEscape(message) + "</p>") +
        "<label>user <input name=\"user\" autocomplete=\"username\" required autofocus></label>"
        "<label>password <input name=\"password\" type=\"password\" autocomplete=\"current-password\" required>"
        "</label><button type=\"submit\">log in</button></form></body></html>\n";
    auto headers = extra;
    headers.emplace_back("Content-Security-Policy",
                         "default-src 'none'; style-src 'unsafe-inline'; form-action 'self'");
    headers.emplace_back("X-Frame-Options", "DENY");
    send(conn, status, "text/html; charset=utf-8", page, headers);
    return status;
}

int redirect(mg_connection* conn, const char* to, const std::vector<std::pair<std::string, std::string>>& extra = {}) {
    auto headers = extra;
    headers.emplace_back("Location", to);
    send(conn, 303, "text/plain", "", headers);
    return 303;
}

std::optional<std::string> cookieToken(const mg_connection* conn) {
    const char* cookies = mg_get_header(conn, "Cookie");
    if (!cookies) return std::nullopt;
    char token[128] = {};
    if (mg_get_cookie(cookies, kSessionCookie, token, sizeof token) <= 0) return std::nullopt;
    return std::string(token);
}

// A form posted from another site's page is refused (browsers send Origin with every POST).
bool sameOrigin(const mg_connection* conn) {
    const char* origin = mg_get_header(conn, "Origin");
    const char* host = mg_get_header(conn, "Host");
    if (!origin) return true;
    return host && std::string_view(origin) == "https://" + std::string(host);
}

}  // namespace

double loginClockS() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

int handleLogin(mg_connection* conn, LoginBook& logins, double max_age_s, const std::string& address,
                const std::function<void(const std::string&, const std::string&)>& audit) {
    const mg_request_info* ri = mg_get_request_info(conn);
    const std::string_view method = ri->request_method;
    if (method == "GET" || method == "HEAD") return sendLoginPage(conn, 200, "");
    if (method != "POST") {
        send(conn, 405, "application/json", "{\"error\":\"GET or POST /login\"}", {{"Allow", "GET, HEAD, POST"}});
        return 405;
    }
    if (!sameOrigin(conn)) return sendLoginPage(conn, 403, "this form was sent from another site's page");
    if (ri->content_length < 0 || ri->content_length > kMaxFormBytes) {
        return sendLoginPage(conn, 413, "the form is too long");
    }
    std::string body(static_cast<size_t>(ri->content_length), '\0');
    size_t got = 0;
    while (got < body.size()) {
        const int n = mg_read(conn, body.data() + got, body.size() - got);
        if (n <= 0) break;
        got += static_cast<size_t>(n);
    }
    body.resize(got);
    char user[128] = {}, password[1024] = {};
    if (mg_get_var(body.data(), body.size(), "user", user, sizeof user) < 0 ||
        mg_get_var(body.data(), body.size(), "password", password, sizeof password) < 0) {
        return sendLoginPage(conn, 400, "the form needs a user and a password");
    }
    if (Status s = logins.reload(); !s.isOk()) {
        std::fprintf(stderr, "facescan view: logins not reloaded: %s (the previous list stays)\n", s.message().c_str());
    }
    const LoginBook::Attempt attempt = logins.login(user, password, address, loginClockS());
    std::memset(password, 0, sizeof password);
    switch (attempt.outcome) {
        case LoginBook::Outcome::kOk: {
            const std::string cookie =
                std::string(kSessionCookie) + "=" + attempt.token +
                "; Path=/; Secure; HttpOnly; SameSite=Strict; Max-Age=" + std::to_string(static_cast<long>(max_age_s));
            std::fprintf(stderr, "facescan view: %s logged in from %s\n", user, address.c_str());
            audit(user, "ok (from " + address + ")");
            return redirect(conn, "/", {{"Set-Cookie", cookie}});
        }
        case LoginBook::Outcome::kLockedOut: {
            const long wait_s = static_cast<long>(std::ceil(attempt.retry_after_s));
            audit(user, "error: locked out after wrong passwords (from " + address + ")");
            return sendLoginPage(conn, 429, "too many wrong passwords: try again in " + std::to_string(wait_s) + " s",
                                 {{"Retry-After", std::to_string(wait_s)}});
        }
        case LoginBook::Outcome::kWrong: break;
    }
    std::fprintf(stderr, "facescan view: a wrong user or password from %s\n", address.c_str());
    audit(user, "error: wrong user or password (from " + address + ")");
    return sendLoginPage(conn, 401, "wrong user or password");
}

int handleLogout(mg_connection* conn, LoginBook& logins) {
    if (!sameOrigin(conn)) return sendLoginPage(conn, 403, "this form was sent from another site's page");
    if (auto token = cookieToken(conn)) logins.logout(*token);
    return redirect(conn, "/login",
                    {{"Set-Cookie", std::string(kSessionCookie) + "=; Path=/; Secure; HttpOnly; SameSite=Strict; "
                                                                  "Max-Age=0"}});
}

std::optional<std::string> sessionUser(const mg_connection* conn, LoginBook& logins) {
    const auto token = cookieToken(conn);
    if (!token) return std::nullopt;
    return logins.check(*token, loginClockS());
}

int refuseWithoutLogin(mg_connection* conn, const std::string& uri) {
    if (uri == "/" || uri == "/index.html") return redirect(conn, "/login");
    send(conn, 401, "application/json", "{\"error\":" + jsonString("log in first (/login)") + "}");
    return 401;
}

}  // namespace facescan::client::detail
