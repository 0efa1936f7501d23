// io/gltf_materials.cpp: materials (the metallic-roughness model and the KHR_materials_*
// extensions read), their textures (KHR_texture_transform, samplers, EXT_texture_webp sources)
// and images, decoded once per (image, colour space) within the texture budget, and a
// material's homogeneous medium (extras.candela_medium, KHR_materials_volume).
#include "gltf_internal.hpp"

#include <cmath>
#include <cstddef>
#include <string>

namespace candela_io::gltf {

int32_t Loader::image_for(int gi, bool srgb, const std::string &what) {
    if (gi < 0 || size_t(gi) >= m_.images.size())
        fail(strf("%s: image %d out of range", what.c_str(), gi));
    const tinygltf::Image &im = m_.images[size_t(gi)];
    const bool from_file = im.bufferView < 0 && !im.uri.empty();
    const std::string file = from_file ? referenced(url_decode(im.uri), what) : std::string();
    const std::string key = from_file ? file : strf("#%d", gi);
    auto it = image_cache_.find({key, srgb ? 1 : 0});
    if (it != image_cache_.end()) return it->second;

    const std::string label = from_file ? "image '" + im.uri + "'" : strf("embedded image %d", gi);
    IoImage img{};
    std::string problem;
    bool ok;
    if (from_file) {
        if (!is_regular_file(file)) fail(label + " not found (" + file + ")");
        ok = candela_io::decode_image(file, nullptr, 0, srgb, true, texture_left(), &img, &problem);
        if (!ok) problem = file + ": " + problem;
    } else if (im.bufferView >= 0) {
        size_t len = m_.bufferViews.size() > size_t(im.bufferView)
                         ? m_.bufferViews[size_t(im.bufferView)].byteLength : 0;
        const unsigned char *p = view_span(im.bufferView, 0, len, label, nullptr);
        ok = candela_io::decode_image(label, p, len, srgb, true, texture_left(), &img, &problem);
    } else {
        if (im.image.empty()) fail(label + " has no data");
        ok = candela_io::decode_image(label, im.image.data(), im.image.size(), srgb, true, texture_left(), &img, &problem);
    }
    if (!ok) fail(label + ": " + problem);
    texture_used_ += io_image_bytes(&img);
    images_.push_back(img);
    const int32_t index = int32_t(images_.size() - 1);
    image_cache_[{key, srgb ? 1 : 0}] = index;
    return index;
}

// A textureInfo inside an extension's JSON (KHR_materials_clearcoat's textures) as tinygltf's
// TextureInfo, for texture_ref: index (-1 when the key is absent), texCoord, extensions.
static tinygltf::TextureInfo texture_info(const tinygltf::Value &ext, const char *key, const std::string &what) {
    tinygltf::TextureInfo ti;
    const tinygltf::Value *v = member(ext, key);
    if (!v) return ti;
    const tinygltf::Value *index = member(*v, "index");
    if (!index || index_value(*index) < 0) fail(what + "." + key + ": needs a texture \"index\"");
    ti.index = index_value(*index);
    if (const tinygltf::Value *tc = member(*v, "texCoord"); tc && index_value(*tc) >= 0) ti.texCoord = index_value(*tc);
    if (const tinygltf::Value *x = member(*v, "extensions"); x && x->IsObject())
        for (const std::string &k : x->Keys()) ti.extensions[k] = x->Get(k);
    return ti;
}

template <class Info>
IoTextureRef Loader::texture_ref(const Info &info, bool srgb, const std::string &what) {
    IoTextureRef r{};
    r.image = -1;
    r.scale[0] = r.scale[1] = 1.0f;
    if (info.index < 0) return r;
    if (size_t(info.index) >= m_.textures.size())
        fail(strf("%s: texture %d out of range", what.c_str(), info.index));
    const tinygltf::Texture &tex = m_.textures[size_t(info.index)];
    r.texcoord = info.texCoord;
    if (const tinygltf::Value *tt = extension(info.extensions, "KHR_texture_transform")) {
        numbers(*tt, "offset", r.offset, 2);
        numbers(*tt, "scale", r.scale, 2);
        r.rotation = float(number_or(*tt, "rotation", 0.0));
        if (const tinygltf::Value *tc = member(*tt, "texCoord"); tc && tc->IsNumber())
            r.texcoord = index_value(*tc) >= 0 ? index_value(*tc) : 0;
    }
    if (r.texcoord != 0 && !warned_texcoord_) {
        warned_texcoord_ = true;
        warn(what + strf(": uses TEXCOORD_%d; only TEXCOORD_0 is loaded", r.texcoord));
    }
    if (tex.sampler >= 0) {
        if (size_t(tex.sampler) >= m_.samplers.size())
            fail(strf("%s: sampler %d out of range", what.c_str(), tex.sampler));
        auto wrap = [](int w) {
            switch (w) {
            case TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE: return 1;
            case TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT: return 2;
            default: return 0;
            }
        };
        r.wrap_s = wrap(m_.samplers[size_t(tex.sampler)].wrapS);
        r.wrap_t = wrap(m_.samplers[size_t(tex.sampler)].wrapT);
    }
    int source = tex.source;
    if (source < 0) {
        if (const tinygltf::Value *webp = extension(tex.extensions, "EXT_texture_webp")) {
            if (const tinygltf::Value *s = member(*webp, "source"); s && s->IsNumber())
                source = index_value(*s);
        }
    }
    if (source < 0) {
        warn(what + strf(": texture %d has no image source; ignored", info.index));
        return r;
    }
    r.image = image_for(source, srgb, what);
    return r;
}

void Loader::convert_materials() {
    materials_.reserve(m_.materials.size());
    for (size_t i = 0; i < m_.materials.size(); ++i) {
        const tinygltf::Material &src = m_.materials[i];
        const std::string what = strf("material '%s'", src.name.c_str());
        IoMaterial d{};
        copy_name(d.name, src.name);
        const auto &pbr = src.pbrMetallicRoughness;
        for (int c = 0; c < 4; ++c)
            d.base_color[c] = pbr.baseColorFactor.size() == 4 ? float(pbr.baseColorFactor[size_t(c)]) : 1.0f;
        d.metallic = float(pbr.metallicFactor);
        d.roughness = float(pbr.roughnessFactor);
        for (int c = 0; c < 3; ++c)
            d.emissive[c] = src.emissiveFactor.size() == 3 ? float(src.emissiveFactor[size_t(c)]) : 0.0f;
        d.emissive_strength = 1.0f;
        d.normal_scale = float(src.normalTexture.scale);
        d.specular = 1.0f;
        d.specular_color[0] = d.specular_color[1] = d.specular_color[2] = 1.0f;
        d.transmission = 0.0f;
        d.ior = 1.5f;
        d.double_sided = src.doubleSided ? 1 : 0;
        if (src.alphaMode == "MASK")
            d.alpha_mode = IO_ALPHA_MASK;
        else if (src.alphaMode == "BLEND")
            d.alpha_mode = IO_ALPHA_BLEND;
        else
            d.alpha_mode = IO_ALPHA_OPAQUE;
        d.alpha_cutoff = float(src.alphaCutoff);

        if (const tinygltf::Value *e = extension(src.extensions, "KHR_materials_emissive_strength"))
            d.emissive_strength = float(number_or(*e, "emissiveStrength", 1.0));
        /* an emission beyond IO_MAX_EMISSION overflowed to infinity in float and rendered a
         * black image with exit 0: refuse it, naming the material */
        for (int c = 0; c < 3; ++c) {
            const double e = double(d.emissive[c]) * double(d.emissive_strength);
            if (!std::isfinite(e) || std::fabs(e) > IO_MAX_EMISSION || !std::isfinite(d.emissive_strength))
                fail(strf("%s: emission out of range (emissiveFactor x emissiveStrength = %g; the limit is %g)",
                          what.c_str(), e, IO_MAX_EMISSION));
        }
        if (const tinygltf::Value *e = extension(src.extensions, "KHR_materials_specular")) {
            d.has_specular_ext = 1;
            d.specular = float(number_or(*e, "specularFactor", 1.0));
            numbers(*e, "specularColorFactor", d.specular_color, 3);
        }
        if (const tinygltf::Value *e = extension(src.extensions, "KHR_materials_transmission"))
            d.transmission = float(number_or(*e, "transmissionFactor", 0.0));
        if (const tinygltf::Value *e = extension(src.extensions, "KHR_materials_ior"))
            d.ior = float(number_or(*e, "ior", 1.5));
        d.clearcoat_tex.image = d.clearcoat_roughness_tex.image = -1;
        if (const tinygltf::Value *e = extension(src.extensions, "KHR_materials_clearcoat")) {
            const std::string w = what + " KHR_materials_clearcoat";
            d.clearcoat = float(finite_number(*e, "clearcoatFactor", 0.0, w));
            d.clearcoat_roughness = float(finite_number(*e, "clearcoatRoughnessFactor", 0.0, w));
            if (!(d.clearcoat >= 0.0f && d.clearcoat <= 1.0f) ||
                !(d.clearcoat_roughness >= 0.0f && d.clearcoat_roughness <= 1.0f))
                fail(w + ": clearcoatFactor and clearcoatRoughnessFactor must be in [0, 1]");
            d.clearcoat_tex = texture_ref(texture_info(*e, "clearcoatTexture", w), false, w + " clearcoatTexture");
            d.clearcoat_roughness_tex =
                texture_ref(texture_info(*e, "clearcoatRoughnessTexture", w), false, w + " clearcoatRoughnessTexture");
            if (member(*e, "clearcoatNormalTexture"))
                warn(w + ": clearcoatNormalTexture is ignored (the coat uses the base's shading normal)");
        }

        d.base_color_tex = texture_ref(pbr.baseColorTexture, true, what + " baseColorTexture");
        d.metallic_roughness_tex =
            texture_ref(pbr.metallicRoughnessTexture, false, what + " metallicRoughnessTexture");
        d.normal_tex = texture_ref(src.normalTexture, false, what + " normalTexture");
        d.emissive_tex = texture_ref(src.emissiveTexture, true, what + " emissiveTexture");
        material_medium(src, what, &d);
        materials_.push_back(d);
    }
}

// The material's homogeneous medium: extras.candela_medium, else KHR_materials_volume (io.h).
void Loader::material_medium(const tinygltf::Material &src, const std::string &what, IoMaterial *d) {
    d->has_medium = 0;
    for (int c = 0; c < 3; ++c) d->medium_sigma_a[c] = d->medium_sigma_s[c] = 0.0f;
    d->medium_anisotropy = 0.0f;
    const char raw = member(src.extras, "candela_medium") ? 0 : raw_member_start(src.extras_json_string, "candela_medium");
    if (raw == '{') {  // an empty object: a medium with the defaults
        d->has_medium = 1;
        return;
    }
    if (raw == '[') fail(what + ": extras.candela_medium must be an object");
    if (const tinygltf::Value *cm = member(src.extras, "candela_medium")) {
        const std::string w = what + ": extras.candela_medium";
        if (!cm->IsObject()) fail(w + " must be an object");
        finite_vec3(*cm, "sigma_a", d->medium_sigma_a, w);
        finite_vec3(*cm, "sigma_s", d->medium_sigma_s, w);
        for (int c = 0; c < 3; ++c) {
            if (d->medium_sigma_a[c] < 0.0f) fail(w + ".sigma_a must not be negative");
            if (d->medium_sigma_s[c] < 0.0f) fail(w + ".sigma_s must not be negative");
        }
        const double g = finite_number(*cm, "anisotropy", 0.0, w);
        if (!(g > -1.0 && g < 1.0)) fail(w + strf(".anisotropy %g is outside (-1, 1)", g));
        d->medium_anisotropy = float(g);
        for (const std::string &k : cm->Keys())
            if (k != "sigma_a" && k != "sigma_s" && k != "anisotropy") warn(w + ": unknown key '" + k + "' ignored");
        d->has_medium = 1;
        return;
    }
    const tinygltf::Value *kv = extension(src.extensions, "KHR_materials_volume");
    if (!kv) return;
    const std::string w = what + ": KHR_materials_volume";
    if (!kv->IsObject()) fail(w + " must be an object");
    double dist = INFINITY;
    if (const tinygltf::Value *v = member(*kv, "attenuationDistance")) {
        if (!v->IsNumber() || !(v->GetNumberAsDouble() > 0.0))
            fail(w + ".attenuationDistance must be a number > 0");
        dist = v->GetNumberAsDouble();
    }
    float color[3] = {1.0f, 1.0f, 1.0f};
    finite_vec3(*kv, "attenuationColor", color, w);
    for (int c = 0; c < 3; ++c)
        if (!(color[c] > 0.0f && color[c] <= 1.0f)) fail(w + ".attenuationColor components must be in (0, 1]");
    if (!std::isfinite(dist) || !std::isfinite(float(dist))) return;  // thin-walled: no medium
    for (int c = 0; c < 3; ++c) {
        const double sa = -std::log(double(color[c])) / dist;
        if (!std::isfinite(float(sa))) fail(w + ": attenuation gives a non-finite absorption coefficient");
        d->medium_sigma_a[c] = float(sa);
        if (d->medium_sigma_a[c] > 0.0f) d->has_medium = 1;
    }
}

}  // namespace candela_io::gltf
